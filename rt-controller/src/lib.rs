//! rt-controller: see issue 5 (not built yet).
