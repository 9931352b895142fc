//! Shared helpers of photomat's integration tests (the test files live in `tests/tests/`).
//!
//! This crate is a workspace member because a bare top-level `tests/` folder is never built
//! in a virtual workspace. It names the plugin crate so the registry sees the built-ins.

use photomat_brdfs as _;
