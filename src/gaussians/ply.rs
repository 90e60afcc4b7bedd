//! Gaussians as 3DGS-layout PLY: `x y z nx ny nz f_dc_0..2 f_rest_0..44 opacity scale_0..2
//! rot_0..3`, binary little-endian float32, parameters stored pre-activation (log-scales,
//! opacity logits, unnormalised quaternions w, x, y, z) exactly as 3DGS writes them, so that our
//! models open in common splat viewers and X-Gaussian / 3DGS checkpoints load.
//!
//! Channels: 3DGS stores three colour channels. Our model has one intensity channel with 16
//! features: writing repeats it in the three channels; reading averages the three (X-Gaussian
//! keeps its channels identical and its renderer averages them, X-Gaussian
//! `gaussian_renderer/__init__.py`). `f_rest` is channel-major
//! as in 3DGS (`f_rest_{c * K + (k - 1)}` for channel c and coefficient k >= 1, K = number of
//! rest coefficients per channel). Files with fewer `f_rest` fields (lower SH degree) load with
//! the missing features at zero.

use std::io::{BufRead, BufReader, Read, Seek};
use std::path::Path;

use ndarray::{Array1, Array2};

use crate::error::{Error, Result};
use crate::gaussians::model::{Gaussians, N_FEATURES};
use crate::real::Real;

/// Write `g` to `path` in the 3DGS layout (binary little-endian float32), atomically.
pub fn write_ply<R: Real>(path: &Path, g: &Gaussians<R>) -> Result<()> {
    write_ply_with_comments(path, g, &[])
}

/// [`write_ply`] with `comment` lines in the header (one line each, no newline inside); other
/// PLY readers ignore them, [`read_ply_with_comments`] returns them.
pub fn write_ply_with_comments<R: Real>(
    path: &Path,
    g: &Gaussians<R>,
    comments: &[String],
) -> Result<()> {
    crate::fsio::write_atomic(path, &ply_bytes(g, comments))
}

/// The bytes of [`write_ply_with_comments`].
pub fn ply_bytes<R: Real>(g: &Gaussians<R>, comments: &[String]) -> Vec<u8> {
    let rest = N_FEATURES - 1;
    let mut header = String::from("ply\nformat binary_little_endian 1.0\n");
    for c in comments {
        header += &format!("comment {}\n", c.replace(['\n', '\r'], " "));
    }
    header += &format!("element vertex {}\n", g.len());
    let mut names: Vec<String> = ["x", "y", "z", "nx", "ny", "nz"]
        .iter()
        .map(|s| s.to_string())
        .collect();
    names.extend((0..3).map(|c| format!("f_dc_{c}")));
    names.extend((0..3 * rest).map(|i| format!("f_rest_{i}")));
    names.push("opacity".into());
    names.extend((0..3).map(|i| format!("scale_{i}")));
    names.extend((0..4).map(|i| format!("rot_{i}")));
    for n in &names {
        header += &format!("property float {n}\n");
    }
    header += "end_header\n";
    let mut buf = Vec::with_capacity(header.len() + g.len() * names.len() * 4);
    buf.extend_from_slice(header.as_bytes());
    let mut put = |v: R| buf.extend_from_slice(&(v.f64() as f32).to_le_bytes());
    for i in 0..g.len() {
        g.means[i].iter().for_each(|&v| put(v));
        (0..3).for_each(|_| put(R::zero()));
        (0..3).for_each(|_| put(g.features[i][0]));
        for _c in 0..3 {
            for k in 1..N_FEATURES {
                put(g.features[i][k]);
            }
        }
        put(g.opacity_logits[i]);
        g.log_scales[i].iter().for_each(|&v| put(v));
        g.quats[i].iter().for_each(|&v| put(v));
    }
    buf
}

#[derive(Clone, Copy, Debug, PartialEq)]
enum Ty {
    I8,
    U8,
    I16,
    U16,
    I32,
    U32,
    F32,
    F64,
}

impl Ty {
    fn parse(s: &str) -> Option<Ty> {
        Some(match s {
            "char" | "int8" => Ty::I8,
            "uchar" | "uint8" => Ty::U8,
            "short" | "int16" => Ty::I16,
            "ushort" | "uint16" => Ty::U16,
            "int" | "int32" => Ty::I32,
            "uint" | "uint32" => Ty::U32,
            "float" | "float32" => Ty::F32,
            "double" | "float64" => Ty::F64,
            _ => return None,
        })
    }
    fn size(self) -> usize {
        match self {
            Ty::I8 | Ty::U8 => 1,
            Ty::I16 | Ty::U16 => 2,
            Ty::I32 | Ty::U32 | Ty::F32 => 4,
            Ty::F64 => 8,
        }
    }
    fn read(self, b: &[u8], big: bool) -> f64 {
        macro_rules! rd {
            ($t:ty, $n:expr) => {{
                let a: [u8; $n] = b[..$n].try_into().unwrap();
                (if big {
                    <$t>::from_be_bytes(a)
                } else {
                    <$t>::from_le_bytes(a)
                }) as f64
            }};
        }
        match self {
            Ty::I8 => b[0] as i8 as f64,
            Ty::U8 => b[0] as f64,
            Ty::I16 => rd!(i16, 2),
            Ty::U16 => rd!(u16, 2),
            Ty::I32 => rd!(i32, 4),
            Ty::U32 => rd!(u32, 4),
            Ty::F32 => rd!(f32, 4),
            Ty::F64 => rd!(f64, 8),
        }
    }
}

/// How a PLY file stores the features: `channels` colour channels (`f_dc_0..channels-1`), each
/// with `rest_per_channel` `f_rest` coefficients (channel-major, see the module header).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FeatureLayout {
    pub channels: usize,
    pub rest_per_channel: usize,
}

/// Read a 3DGS-layout PLY (binary little/big endian or ASCII). The three colour channels are
/// averaged into our single intensity channel. Errors name the file and the missing or bad field.
pub fn read_ply<R: Real>(path: &Path) -> Result<Gaussians<R>> {
    read_ply_full(path).map(|(g, _, _)| g)
}

/// [`read_ply`], also returning the file's [`FeatureLayout`].
pub fn read_ply_with_layout<R: Real>(path: &Path) -> Result<(Gaussians<R>, FeatureLayout)> {
    read_ply_full(path).map(|(g, l, _)| (g, l))
}

/// [`read_ply`] and the header's `comment` lines (without the `comment ` prefix), in order.
pub fn read_ply_with_comments<R: Real>(path: &Path) -> Result<(Gaussians<R>, Vec<String>)> {
    read_ply_full(path).map(|(g, _, c)| (g, c))
}

/// [`read_ply`] with the file's [`FeatureLayout`] and header comments.
pub fn read_ply_full<R: Real>(path: &Path) -> Result<(Gaussians<R>, FeatureLayout, Vec<String>)> {
    let mut comments = Vec::new();
    let file = std::fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let meta = file.metadata().map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        return Err(Error::format(
            path,
            "file",
            "not a regular file: only regular files are read",
        ));
    }
    let file_len = meta.len();
    let mut rd = BufReader::new(file);
    let mut line = String::new();
    let mut header_bytes = 0usize;
    let mut read_line = |rd: &mut BufReader<std::fs::File>, line: &mut String| -> Result<()> {
        line.clear();
        // A header line is at most 4 KiB and the header at most 1 MiB.
        let n = rd
            .by_ref()
            .take(4096)
            .read_line(line)
            .map_err(|e| Error::format(path, "header", format!("not a text line: {e}")))?;
        header_bytes += n;
        if header_bytes > 1 << 20 || (n == 4096 && !line.ends_with('\n')) {
            return Err(Error::format(
                path,
                "header",
                "header line over 4 KiB or header over 1 MiB: not a PLY header",
            ));
        }
        if n == 0 {
            return Err(Error::format(
                path,
                "header",
                "file ends before `end_header`",
            ));
        }
        Ok(())
    };
    read_line(&mut rd, &mut line)?;
    if line.trim_end() != "ply" {
        return Err(Error::format(
            path,
            "magic",
            "not a PLY file (first line is not `ply`)",
        ));
    }
    let mut format = None;
    let mut n_vertex: Option<usize> = None;
    let mut props: Vec<(String, Ty)> = Vec::new();
    let mut in_vertex = false;
    loop {
        read_line(&mut rd, &mut line)?;
        let t: Vec<&str> = line.split_whitespace().collect();
        if let Some(c) = line.strip_prefix("comment ") {
            comments.push(c.trim_end_matches(['\n', '\r']).to_string());
            continue;
        }
        match t.as_slice() {
            ["end_header"] => break,
            ["format", f, _] => format = Some(f.to_string()),
            ["element", name, n] => {
                // Elements after the vertices are ignored (they come after them in the body).
                in_vertex = *name == "vertex";
                if in_vertex {
                    n_vertex = Some(n.parse().map_err(|_| {
                        Error::format(path, "element vertex", format!("bad count `{n}`"))
                    })?);
                } else if n_vertex.is_none() {
                    return Err(Error::format(
                        path,
                        "element",
                        format!("element `{name}` before `vertex` is not supported"),
                    ));
                }
            }
            ["property", "list", ..] if in_vertex => {
                return Err(Error::format(
                    path,
                    "property",
                    "list properties in `vertex` are not supported",
                ));
            }
            ["property", ty, name] if in_vertex => {
                let ty = Ty::parse(ty).ok_or_else(|| {
                    Error::format(
                        path,
                        format!("property {name}"),
                        format!("unknown type `{ty}`"),
                    )
                })?;
                props.push((name.to_string(), ty));
            }
            _ => {}
        }
    }
    let n = n_vertex.ok_or_else(|| Error::format(path, "element vertex", "missing"))?;
    let format = format.ok_or_else(|| Error::format(path, "format", "missing"))?;
    let col = |name: &str| -> Result<usize> {
        props
            .iter()
            .position(|(p, _)| p == name)
            .ok_or_else(|| Error::format(path, name, "missing property"))
    };
    let ix_mean = [col("x")?, col("y")?, col("z")?];
    let ix_scale = [col("scale_0")?, col("scale_1")?, col("scale_2")?];
    let ix_rot = [col("rot_0")?, col("rot_1")?, col("rot_2")?, col("rot_3")?];
    let ix_op = col("opacity")?;
    let ix_dc: Vec<usize> = (0..3)
        .filter_map(|c| col(&format!("f_dc_{c}")).ok())
        .collect();
    if ix_dc.is_empty() {
        return Err(Error::format(path, "f_dc_0", "missing property"));
    }
    let n_rest_total = props
        .iter()
        .filter(|(p, _)| p.starts_with("f_rest_"))
        .count();
    let ch = ix_dc.len();
    if n_rest_total % ch != 0 {
        return Err(Error::format(
            path,
            "f_rest_*",
            format!("{n_rest_total} fields do not split into {ch} channels"),
        ));
    }
    let k_rest = (n_rest_total / ch).min(N_FEATURES - 1);
    let per_ch = n_rest_total / ch;
    let mut ix_rest = vec![vec![0usize; k_rest]; ch];
    for (c, row) in ix_rest.iter_mut().enumerate() {
        for (k, slot) in row.iter_mut().enumerate() {
            *slot = col(&format!("f_rest_{}", c * per_ch + k))?;
        }
    }

    let mut values = vec![0f64; props.len()];
    // Claimed sizes are checked against the file length before anything is allocated: a
    // binary vertex takes `stride` bytes, an ascii one at least 2 bytes per property.
    let stride: usize = props.iter().map(|(_, t)| t.size()).sum();
    let per_vertex = if format == "ascii" {
        2 * props.len()
    } else {
        stride
    };
    let body_len = file_len.saturating_sub(rd.stream_position().map_err(|e| Error::io(path, e))?);
    match n.checked_mul(per_vertex) {
        Some(b) if b as u64 <= body_len.saturating_add(1) => {}
        _ => {
            return Err(Error::format(
                path,
                "element vertex",
                format!(
                    "{n} vertices of at least {per_vertex} bytes do not fit in the {body_len} \
                     bytes after the header (a false count, or a truncated file)"
                ),
            ))
        }
    }
    let mut g = Gaussians::<R>::zeros(n);
    let mut body = Vec::new();
    rd.take(body_len)
        .read_to_end(&mut body)
        .map_err(|e| Error::io(path, e))?;
    let mut ascii = match format.as_str() {
        "ascii" => Some(
            std::str::from_utf8(&body)
                .map_err(|_| Error::format(path, "format", "ascii body is not UTF-8"))?
                .split_whitespace(),
        ),
        "binary_little_endian" | "binary_big_endian" => {
            if body.len() < n * stride {
                return Err(Error::format(
                    path,
                    "element vertex",
                    format!(
                        "body has {} bytes, {} vertices need {}",
                        body.len(),
                        n,
                        n * stride
                    ),
                ));
            }
            None
        }
        other => {
            return Err(Error::format(
                path,
                "format",
                format!("unknown format `{other}`"),
            ))
        }
    };
    let big = format == "binary_big_endian";
    for i in 0..n {
        match ascii.as_mut() {
            Some(it) => {
                for (p, v) in values.iter_mut().enumerate() {
                    let tok = it.next().ok_or_else(|| {
                        Error::format(
                            path,
                            "element vertex",
                            format!("ascii body ends at vertex {i}"),
                        )
                    })?;
                    *v = tok.parse().map_err(|_| {
                        Error::format(path, &props[p].0, format!("vertex {i}: bad number `{tok}`"))
                    })?;
                }
            }
            None => {
                let mut off = i * stride;
                for (p, v) in values.iter_mut().enumerate() {
                    *v = props[p].1.read(&body[off..], big);
                    off += props[p].1.size();
                }
            }
        }
        for a in 0..3 {
            g.means[i][a] = R::c(values[ix_mean[a]]);
            g.log_scales[i][a] = R::c(values[ix_scale[a]]);
        }
        for a in 0..4 {
            g.quats[i][a] = R::c(values[ix_rot[a]]);
        }
        g.opacity_logits[i] = R::c(values[ix_op]);
        g.features[i][0] = R::c(ix_dc.iter().map(|&c| values[c]).sum::<f64>() / ch as f64);
        for k in 0..k_rest {
            g.features[i][k + 1] =
                R::c(ix_rest.iter().map(|row| values[row[k]]).sum::<f64>() / ch as f64);
        }
    }
    g.check_finite()
        .map_err(|e| Error::format(path, "vertex", e.to_string()))?;
    Ok((
        g,
        FeatureLayout {
            channels: ch,
            rest_per_channel: per_ch,
        },
        comments,
    ))
}

/// Gradients with respect to the fields stored in a PLY of layout `layout` (pre-activation, as
/// stored), widened to f64: `xyz` [N, 3], `features` [N, C + C K] (`f_dc_0..C-1`, then
/// `f_rest_{c K + (k - 1)}`, channel-major as stored), `opacity` \[N\] (logit), `scale` [N, 3]
/// (log-scale), `rot` [N, 4] (w, x, y, z).
#[derive(Clone, Debug, PartialEq)]
pub struct StoredGrads {
    pub xyz: Array2<f64>,
    pub features: Array2<f64>,
    pub opacity: Array1<f64>,
    pub scale: Array2<f64>,
    pub rot: Array2<f64>,
}

impl StoredGrads {
    /// Map the gradient `d` of our model (one channel, [`N_FEATURES`] features) to the stored
    /// fields. [`read_ply`] averages the C channels, so each stored channel gets 1/C of the
    /// gradient of the averaged feature; coefficients beyond our 16 features are not read and
    /// get 0.
    pub fn new<R: Real>(d: &Gaussians<R>, layout: FeatureLayout) -> Self {
        let n = d.len();
        let f = |x: R| x.f64();
        let (ch, k_rest) = (layout.channels, layout.rest_per_channel);
        let share = 1.0 / ch as f64;
        let features = Array2::from_shape_fn((n, ch + ch * k_rest), |(i, j)| {
            let k = if j < ch { 0 } else { (j - ch) % k_rest + 1 };
            d.features[i].get(k).map_or(0.0, |&x| f(x) * share)
        });
        StoredGrads {
            xyz: Array2::from_shape_fn((n, 3), |(i, a)| f(d.means[i][a])),
            features,
            opacity: Array1::from_shape_fn(n, |i| f(d.opacity_logits[i])),
            scale: Array2::from_shape_fn((n, 3), |(i, a)| f(d.log_scales[i][a])),
            rot: Array2::from_shape_fn((n, 4), |(i, a)| f(d.quats[i][a])),
        }
    }

    /// Write the five arrays to an npz file (keys `xyz`, `features`, `opacity`, `scale`, `rot`).
    pub fn write_npz(&self, path: &Path) -> Result<()> {
        let npz_err = |e: ndarray_npy::WriteNpzError| Error::format(path, "npz", e.to_string());
        let file = std::fs::File::create(path).map_err(|e| Error::io(path, e))?;
        let mut npz = ndarray_npy::NpzWriter::new(file);
        npz.add_array("xyz", &self.xyz).map_err(npz_err)?;
        npz.add_array("features", &self.features).map_err(npz_err)?;
        npz.add_array("opacity", &self.opacity).map_err(npz_err)?;
        npz.add_array("scale", &self.scale).map_err(npz_err)?;
        npz.add_array("rot", &self.rot).map_err(npz_err)?;
        npz.finish().map_err(npz_err)?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample(n: usize) -> Gaussians<f64> {
        let mut g = Gaussians::<f64>::zeros(n);
        for i in 0..n {
            let x = i as f64;
            g.means[i] = [x, -2.0 * x, 0.5 + x];
            g.log_scales[i] = [-1.0 - x, 0.25, 1.5];
            g.quats[i] = [1.0, 0.1 * x, -0.2, 0.3];
            g.opacity_logits[i] = -2.0 + x;
            for k in 0..N_FEATURES {
                g.features[i][k] = 0.125 * (k as f64) - x;
            }
        }
        g
    }

    #[test]
    fn round_trip_is_exact_in_f32() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("m.ply");
        let g = sample(5);
        write_ply(&p, &g).unwrap();
        let back: Gaussians<f64> = read_ply(&p).unwrap();
        let expect = g.cast::<f32>().cast::<f64>();
        assert_eq!(back, expect);
    }

    #[test]
    fn channels_are_averaged_and_short_rest_is_zero_padded() {
        // An ASCII file with SH degree 1 (3 rest coefficients per channel) and distinct channels.
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("a.ply");
        let mut s = String::from("ply\nformat ascii 1.0\nelement vertex 1\n");
        for n in ["x", "y", "z", "f_dc_0", "f_dc_1", "f_dc_2"] {
            s += &format!("property float {n}\n");
        }
        for i in 0..9 {
            s += &format!("property float f_rest_{i}\n");
        }
        for n in [
            "opacity", "scale_0", "scale_1", "scale_2", "rot_0", "rot_1", "rot_2", "rot_3",
        ] {
            s += &format!("property double {n}\n");
        }
        s += "end_header\n1 2 3  0.1 0.2 0.3  1 2 3 4 5 6 7 8 9  0.5 -1 -2 -3 1 0 0 0\n";
        std::fs::write(&p, s).unwrap();
        let g: Gaussians<f64> = read_ply(&p).unwrap();
        assert!((g.features[0][0] - 0.2).abs() < 1e-7);
        // f_rest is channel-major: coefficient 1 is f_rest_0, f_rest_3, f_rest_6 -> mean 4.
        assert_eq!(&g.features[0][1..4], &[4.0, 5.0, 6.0]);
        assert!(g.features[0][4..].iter().all(|&v| v == 0.0));
        assert_eq!(g.log_scales[0], [-1.0, -2.0, -3.0]);
    }

    #[test]
    fn missing_property_and_truncated_body_are_named() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("bad.ply");
        std::fs::write(&p, "ply\nformat binary_little_endian 1.0\nelement vertex 1\nproperty float x\nend_header\n").unwrap();
        let e = read_ply::<f32>(&p).unwrap_err().to_string();
        assert!(e.contains("bad.ply") && e.contains("`y`"), "{e}");
        let g = sample(3);
        write_ply(&p, &g).unwrap();
        let bytes = std::fs::read(&p).unwrap();
        std::fs::write(&p, &bytes[..bytes.len() - 10]).unwrap();
        let e = read_ply::<f32>(&p).unwrap_err().to_string();
        assert!(e.contains("element vertex"), "{e}");
        std::fs::write(&p, "not a ply").unwrap();
        assert!(read_ply::<f32>(&p)
            .unwrap_err()
            .to_string()
            .contains("magic"));
    }

    /// An ASCII PLY with `ch` channels and `k` rest coefficients per channel, feature values
    /// `vals` (f_dc_0..ch-1 then f_rest_0..ch*k-1).
    fn ascii_ply(path: &Path, ch: usize, k: usize, vals: &[f64]) {
        let mut s = String::from("ply\nformat ascii 1.0\nelement vertex 1\n");
        let mut names: Vec<String> = ["x", "y", "z"].map(String::from).to_vec();
        names.extend((0..ch).map(|c| format!("f_dc_{c}")));
        names.extend((0..ch * k).map(|i| format!("f_rest_{i}")));
        names.extend(["opacity", "scale_0", "scale_1", "scale_2"].map(String::from));
        names.extend(["rot_0", "rot_1", "rot_2", "rot_3"].map(String::from));
        for n in &names {
            s += &format!("property double {n}\n");
        }
        s += "end_header\n1 2 3";
        for v in vals
            .iter()
            .chain(&[0.5, -1.0, -2.0, -3.0, 1.0, 0.0, 0.0, 0.0])
        {
            s += &format!(" {v}");
        }
        std::fs::write(path, s + "\n").unwrap();
    }

    /// The stored-field gradient of L = sum_k w_k f_k (f = features as read) against exact
    /// differences of L through `read_ply` (the read is linear in the stored features), for
    /// 3 channels, 1 channel, and more rest coefficients than the model keeps.
    #[test]
    fn stored_grads_are_the_gradient_of_the_read() {
        let dir = tempfile::tempdir().unwrap();
        let p = dir.path().join("g.ply");
        let w: Vec<f64> = (0..N_FEATURES).map(|k| 0.5 + 0.25 * k as f64).collect();
        let loss =
            |g: &Gaussians<f64>| -> f64 { g.features[0].iter().zip(&w).map(|(a, b)| a * b).sum() };
        for (ch, k) in [(3, 3), (1, 15), (3, 15), (2, 20)] {
            let base: Vec<f64> = (0..ch + ch * k).map(|j| 0.125 * j as f64 - 1.0).collect();
            ascii_ply(&p, ch, k, &base);
            let (g0, layout): (Gaussians<f64>, _) = read_ply_with_layout(&p).unwrap();
            assert_eq!(
                layout,
                FeatureLayout {
                    channels: ch,
                    rest_per_channel: k
                }
            );
            let mut d = Gaussians::<f64>::zeros(1);
            d.features[0].copy_from_slice(&w);
            let sg = StoredGrads::new(&d, layout);
            assert_eq!(sg.features.dim(), (1, ch + ch * k));
            for j in 0..base.len() {
                let mut v = base.clone();
                v[j] += 1.0;
                ascii_ply(&p, ch, k, &v);
                let fd = loss(&read_ply(&p).unwrap()) - loss(&g0);
                assert!(
                    (sg.features[[0, j]] - fd).abs() < 1e-12,
                    "{ch} {k} {j}: {} vs {fd}",
                    sg.features[[0, j]]
                );
            }
        }
    }
}
