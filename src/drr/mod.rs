//! Digitally reconstructed radiographs: line integrals of a volume along the rays of a
//! [`crate::geometry::Camera`], exact (Siddon) or sampled (trilinear ray-march).

pub mod siddon;
pub mod trilinear;
