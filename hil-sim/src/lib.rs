//! Simulated imucal board (work in progress).
#![forbid(unsafe_code)]
