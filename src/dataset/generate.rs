//! Dataset generation with the paper protocol (not written yet).
