//! The trainer: method presets, the training loop and its progress events.

pub mod config;
