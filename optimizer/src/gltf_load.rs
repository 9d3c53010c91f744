//! Safe glTF loading (work in progress).
