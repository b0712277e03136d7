#!/usr/bin/env bash
# Runs the workspace's property tests once per seed, each
# property test drawing its cases from that seed instead of its fixed one
# (fshape_mesh::test_support::strategies::config; README, "Development"):
#   scripts/proptest-seeds.sh FIRST LAST [CASES]
# e.g. `scripts/proptest-seeds.sh 1 50` or `scripts/proptest-seeds.sh 7 7 1000`.
# Prints one line per seed and, for a failing seed, the failing tests with
# their minimal inputs; exits non-zero if any seed failed.
set -euo pipefail
first=${1:?first seed}
last=${2:?last seed}
cases=${3:-}
cd "$(dirname "$0")/.."
crates=(-p fshape-mesh -p fshape-fem -p fshape-kernels -p fshape-validate)
# The property tests (a new one is added here): a name filters the tests
# of every binary, so the deterministic tests around them do not rerun.
tests=(
    the_f64_local_matrix_equals_the_generic_one every_norm_is_positive_definite
    mixed_precision_sums_are_within_the_stated_bound conv_matches_the_brute_force_oracle
    the_bvh_finds_the_runs_of_the_scan every_format_round_trips_exactly ply_rs_reads_our_ply
    vtkio_reads_our_vtk the_law_holds_for_random_smooth_tangent_fields
    the_law_holds_along_random_horizontal_trajectories rk4_conserves_h_to_fourth_order
    the_midpoint_scheme_conserves_h_to_second_order euler_conserves_h_to_first_order
)
cargo test "${crates[@]}" --no-run --quiet
failed=0
for seed in $(seq "$first" "$last"); do
    log=$(mktemp)
    if FSHAPE_PROPTEST_SEED=$seed ${cases:+FSHAPE_PROPTEST_CASES=$cases} cargo test "${crates[@]}" --quiet -- "${tests[@]}" >"$log" 2>&1; then
        echo "seed $seed: ok"
    else
        echo "seed $seed: FAILED"
        grep -E "^test .* FAILED|Test failed|minimal failing input" "$log" || tail -20 "$log"
        failed=1
    fi
    rm -f "$log"
done
exit $failed
