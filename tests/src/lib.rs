//! Workspace integration tests live in `tests/tests/`; this library only shares helpers.
