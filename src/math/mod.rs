//! Maths shared by forward and backward passes: quaternions, covariances, 2x2 inverses,
//! activations, each with its vector-Jacobian product.
