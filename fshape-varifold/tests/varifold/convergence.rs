//! Convergence under refinement (placeholder filled below).
