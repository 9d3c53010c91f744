//! HTTP service over the [`optimizer`] library.
//!
//! The service is thin: it validates, schedules, stores and serves; every
//! geometric computation lives in the `optimizer` crate. Until the service is
//! built out this crate only re-exports the library version it serves.

/// Version of the optimizer library this service is built against.
pub const OPTIMIZER_VERSION: &str = optimizer::VERSION;
