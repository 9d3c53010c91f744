//! Procedural Vienna-like city generator (work in progress).
