//! One module per command: its arguments (`Args`, clap's derive) and its
//! `run`.

pub mod atlas;
pub mod batch;
pub mod checkpoint;
pub mod convert;
pub mod demo;
pub mod distance;
pub mod fem;
pub mod info;
pub mod matching;
pub mod quality;
pub mod regress;
pub mod render;
pub mod report;
pub mod shoot;
pub mod stats;
pub mod transfer;
