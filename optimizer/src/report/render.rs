//! HTML and CSV rendering of a [`super::Report`] (placeholder).
