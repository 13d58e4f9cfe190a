//! Helpers shared by the integration tests (see the `[[test]]` files).
