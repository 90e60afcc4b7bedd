//! The field model file: a `.npz` of named arrays that numpy reads with `numpy.load`.
//!
//! Arrays (every float array f32):
//! - `mlp_meta` (i64 `[4]`): `num_layers`, `hidden_dim`, encoder output width, output
//!   activation (0 sigmoid, 1 LeakyReLU 0.01, 2 softplus);
//! - `skips` (i64): layers whose input is `concat([encoding, h])`;
//! - `w{i}` (`[in, out]`) and `b{i}` (`[out]`) for layer `i`: `z = x @ w{i} + b{i}`, LeakyReLU
//!   0.01 after every layer but the last;
//! - frequency encoder: `freq_bands` (i64 `[1]`): `[x, sin(2^0 x), cos(2^0 x), ...]` of the
//!   point in metres, each block 3-wide;
//! - hash grid: `hash_meta` (i64 `[4]`: levels, features, log2 table size, base resolution),
//!   `hash_offsets` (i64 `[levels + 1]`, first entry of each level), `hash_table`
//!   (`[entries, features]`), `bound` (f64 `[1]`, metres); indexing as in
//!   [`super::encode::hash_grid`];
//! - TensoRF VM: `vm_meta` (i64 `[4]`: resolution N, components C, output width, line mode 0
//!   upstream (the line factor reads the plane's column at x = 0) / 1 corrected),
//!   `vm_planes` (`[3, C, N, N]`, PyTorch's `density_plane` stacked), `vm_lines`
//!   (`[3, C, N]`), `vm_basis` (`[out, 3C]`, `basis_mat.weight`), `bound`; reads as in
//!   [`super::encode::tensor_vm`];
//! - dense grid: `dense_table` (`[N, N, N, F]`, indexed `[z, y, x]`), `bound`; reads as in
//!   [`super::encode::dense_grid`] (align-corners mapping).
//!
//! The density at a point `p` (metres, clamped to `+-(bound - 1e-6)`) is the MLP applied to
//! the encoding; it is the volume value divided by the dataset volume's maximum (see
//! [`super::train`]).

use std::path::Path;

use ndarray::{Array1, Array2};
use ndarray_npy::NpzWriter;

use super::encode::Encoder;
use super::mlp::OutAct;
use super::Field;
use crate::error::{Error, Result};

/// Write `field` to `path` (see the module doc).
pub fn save(path: &Path, field: &Field<f32>) -> Result<()> {
    let file = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
    let mut npz = NpzWriter::new(file);
    let err = |e: ndarray_npy::WriteNpzError| Error::format(path, "npz", e.to_string());
    let mlp = &field.mlp;
    let act = match mlp.out_act {
        OutAct::Sigmoid => 0i64,
        OutAct::LeakyRelu => 1,
        OutAct::Softplus => 2,
    };
    npz.add_array(
        "mlp_meta",
        &Array1::from(vec![
            mlp.layers as i64,
            mlp.hidden as i64,
            mlp.in_dim as i64,
            act,
        ]),
    )
    .map_err(err)?;
    npz.add_array(
        "skips",
        &Array1::from(mlp.skips.iter().map(|&s| s as i64).collect::<Vec<_>>()),
    )
    .map_err(err)?;
    let ne = field.n_encoder_params();
    let mp = &field.params[ne..];
    for (i, &(inp, out, off)) in mlp.shape.iter().enumerate() {
        let w = Array2::from_shape_vec((inp, out), mp[off..off + inp * out].to_vec())
            .map_err(|e| Error::format(path, format!("w{i}"), e.to_string()))?;
        npz.add_array(format!("w{i}"), &w).map_err(err)?;
        let b = Array1::from(mp[off + inp * out..off + inp * out + out].to_vec());
        npz.add_array(format!("b{i}"), &b).map_err(err)?;
    }
    match &field.encoder {
        Encoder::Frequency(f) => {
            npz.add_array("freq_bands", &Array1::from(vec![f.bands as i64]))
                .map_err(err)?;
        }
        Encoder::HashGrid(h) => {
            npz.add_array(
                "hash_meta",
                &Array1::from(vec![
                    h.levels as i64,
                    h.features as i64,
                    h.log2_table as i64,
                    h.base as i64,
                ]),
            )
            .map_err(err)?;
            npz.add_array(
                "hash_offsets",
                &Array1::from(h.offsets.iter().map(|&o| o as i64).collect::<Vec<_>>()),
            )
            .map_err(err)?;
            let t = Array2::from_shape_vec(
                (h.offsets[h.levels], h.features),
                field.params[..ne].to_vec(),
            )
            .map_err(|e| Error::format(path, "hash_table", e.to_string()))?;
            npz.add_array("hash_table", &t).map_err(err)?;
            npz.add_array("bound", &Array1::from(vec![h.bound]))
                .map_err(err)?;
        }
        Encoder::TensorVm(v) => {
            let (n, c) = (v.resolution, v.components);
            let (loff, boff) = v.offsets();
            let lines = match v.lines {
                super::encode::VmLines::Upstream => 0i64,
                super::encode::VmLines::Corrected => 1,
            };
            npz.add_array(
                "vm_meta",
                &Array1::from(vec![n as i64, c as i64, v.out_dim as i64, lines]),
            )
            .map_err(err)?;
            let p = &field.params[..ne];
            let shape_err = |k: &str, e: ndarray::ShapeError| Error::format(path, k, e.to_string());
            let planes = ndarray::Array4::from_shape_vec((3, c, n, n), p[..loff].to_vec())
                .map_err(|e| shape_err("vm_planes", e))?;
            npz.add_array("vm_planes", &planes).map_err(err)?;
            let l = ndarray::Array3::from_shape_vec((3, c, n), p[loff..boff].to_vec())
                .map_err(|e| shape_err("vm_lines", e))?;
            npz.add_array("vm_lines", &l).map_err(err)?;
            let b = Array2::from_shape_vec((v.out_dim, 3 * c), p[boff..].to_vec())
                .map_err(|e| shape_err("vm_basis", e))?;
            npz.add_array("vm_basis", &b).map_err(err)?;
            npz.add_array("bound", &Array1::from(vec![v.bound]))
                .map_err(err)?;
        }
        Encoder::DenseGrid(d) => {
            let n = d.resolution;
            let t =
                ndarray::Array4::from_shape_vec((n, n, n, d.features), field.params[..ne].to_vec())
                    .map_err(|e| Error::format(path, "dense_table", e.to_string()))?;
            npz.add_array("dense_table", &t).map_err(err)?;
            npz.add_array("bound", &Array1::from(vec![d.bound]))
                .map_err(err)?;
        }
    }
    npz.finish().map_err(err)?;
    Ok(())
}
