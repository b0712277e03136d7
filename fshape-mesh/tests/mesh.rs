//! Integration tests of fshape-mesh (one binary, modules in `tests/mesh/`).

#[path = "mesh/data.rs"]
mod data;
#[path = "mesh/geometry.rs"]
mod geometry;
#[path = "mesh/malformed.rs"]
mod malformed;
#[path = "mesh/nibabel.rs"]
mod nibabel;
#[path = "mesh/roundtrip.rs"]
mod roundtrip;
#[path = "mesh/simplify.rs"]
mod simplify;
#[path = "mesh/validation.rs"]
mod validation;

use std::path::PathBuf;

/// A file shipped in the repository's `data/` folder.
pub fn data(rel: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../data").join(rel)
}
