#!/usr/bin/env bash
# The paper's sphere figure (fig:metam_sphere) as docs/sphere_geodesics.png:
# r_t and f_t for its three settings, the derived ODE, the ODE with the
# paper's 4π, and discrete shooting. Installs matplotlib in
# target/python-venv; runs the Rust example that computes the curves.
# Usage: scripts/sphere_plot.sh
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
py="$("$here/python-env.sh")"
"$(dirname "$py")/pip" install --quiet matplotlib==3.11.2 >&2
(cd "$here/.." && cargo run --release --quiet -p fshape-validate --example sphere_plots)
"$py" "$here/sphere_plot.py"
