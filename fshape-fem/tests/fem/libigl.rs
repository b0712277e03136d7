//! Reference values from libigl: see tests/reference/README.md.
