//! DRR benchmark (placeholder, filled below).
