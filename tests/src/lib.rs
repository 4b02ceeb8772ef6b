//! Cross-process integration tests live in `tests/tests/` (issue 5).
