//! Atomic file writes and output-folder hygiene, shared by run folders
//! ([`crate::train::run_dir`]), dataset folders ([`crate::dataset::store`]) and the CLI.
//!
//! [`write_atomic`] writes the bytes to a temporary name in the same folder
//! (`.NAME.tmp`), flushes them to disk, and renames the temporary file onto `NAME`. A reader
//! therefore sees either the old file or the complete new one, never a partial file; a failed
//! write (disk full, permission) removes the temporary file and leaves the old file as it was,
//! so no 0-byte or truncated output is left behind.
//!
//! [`write_atomic`]: crate::fsio::write_atomic

use std::io::Write;
use std::path::{Path, PathBuf};

use crate::error::{Error, Result};

/// The temporary name [`write_atomic`] uses for `path`: `.NAME.tmp` beside it.
pub fn temp_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map(|n| n.to_string_lossy().to_string())
        .unwrap_or_default();
    path.with_file_name(format!(".{name}.tmp"))
}

/// Write `bytes` to `path` atomically (temporary name, fsync, rename). On error the temporary
/// file is removed and `path` is unchanged.
pub fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    let tmp = temp_path(path);
    let res = (|| -> std::io::Result<()> {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()
    })();
    if let Err(e) = res {
        let _ = std::fs::remove_file(&tmp);
        return Err(Error::io(path, e));
    }
    std::fs::rename(&tmp, path).map_err(|e| {
        let _ = std::fs::remove_file(&tmp);
        Error::io(path, e)
    })
}

/// [`write_atomic`] of pretty-printed JSON with a final newline.
pub fn write_json_atomic<T: serde::Serialize + ?Sized>(path: &Path, value: &T) -> Result<()> {
    let mut s = serde_json::to_string_pretty(value)
        .map_err(|e| Error::format(path, "json", e.to_string()))?;
    s.push('\n');
    write_atomic(path, s.as_bytes())
}

/// A grey 8-bit image encoded as PNG in memory and written with [`write_atomic`].
pub fn write_png_atomic(path: &Path, img: &image::GrayImage) -> Result<()> {
    let mut buf = std::io::Cursor::new(Vec::new());
    img.write_to(&mut buf, image::ImageFormat::Png)
        .map_err(|e| Error::format(path, "png", e.to_string()))?;
    write_atomic(path, buf.get_ref())
}

/// Remove `path` if it exists (file or folder); a missing path is not an error.
pub fn remove_if_exists(path: &Path) -> Result<()> {
    let r = match std::fs::symlink_metadata(path) {
        Err(_) => return Ok(()),
        Ok(m) if m.is_dir() => std::fs::remove_dir_all(path),
        Ok(_) => std::fs::remove_file(path),
    };
    match r {
        Err(e) if e.kind() != std::io::ErrorKind::NotFound => Err(Error::io(path, e)),
        _ => Ok(()),
    }
}

/// Remove the files of folder `dir` whose name starts with `prefix` and ends with `suffix`
/// (stale outputs of an earlier command, e.g. `view_*.png`). A missing folder is not an error.
pub fn remove_matching(dir: &Path, prefix: &str, suffix: &str) -> Result<()> {
    let rd = match std::fs::read_dir(dir) {
        Ok(rd) => rd,
        Err(_) => return Ok(()),
    };
    for e in rd {
        let e = e.map_err(|e| Error::io(dir, e))?;
        let name = e.file_name().to_string_lossy().to_string();
        if name.starts_with(prefix) && name.ends_with(suffix) && e.path().is_file() {
            std::fs::remove_file(e.path()).map_err(|err| Error::io(e.path(), err))?;
        }
    }
    Ok(())
}

/// Error when the input file `input` is one of the files `outputs` a command is about to
/// write (compared after resolving symlinks and `..`), so that no command overwrites its own
/// input. `field` names the input flag.
pub fn check_not_output(field: &str, input: &Path, outputs: &[PathBuf]) -> Result<()> {
    let Ok(inp) = input.canonicalize() else {
        return Ok(());
    };
    for o in outputs {
        let same = match o.canonicalize() {
            Ok(c) => c == inp,
            // Not there yet: compare the canonical parent plus the name.
            Err(_) => match (o.parent().map(|p| p.canonicalize()), o.file_name()) {
                (Some(Ok(p)), Some(n)) => p.join(n) == inp,
                _ => false,
            },
        };
        if same {
            return Err(Error::invalid(
                field,
                format!(
                    "{} is also an output of this command and would be overwritten; write to \
                     another folder",
                    input.display()
                ),
            ));
        }
    }
    Ok(())
}

/// The start of a framed binary file (the checkpoints): `magic`, a little-endian u64 header
/// length, the header as JSON; the payload follows, and [`seal`] ends the file with a checksum.
pub fn frame_header<H: serde::Serialize>(magic: &[u8], header: &H) -> Vec<u8> {
    let hj = serde_json::to_vec(header).expect("header serialises");
    let mut b = Vec::with_capacity(magic.len() + 8 + hj.len());
    b.extend_from_slice(magic);
    b.extend_from_slice(&(hj.len() as u64).to_le_bytes());
    b.extend_from_slice(&hj);
    b
}

/// End a framed file: append the [`crate::fingerprint::Words`] hash of every byte before it
/// (8 bytes, little-endian), which [`read_frame`] checks.
pub fn seal(buf: &mut Vec<u8>) {
    let h = crate::fingerprint::Words::default().bytes(buf).finish();
    buf.extend_from_slice(&h.to_le_bytes());
}

/// The bytes of a [`seal`]ed file without the checksum, after checking it.
fn unseal<'a>(path: &Path, bytes: &'a [u8]) -> Result<&'a [u8]> {
    let corrupt = || {
        Error::format(
            path,
            "checksum",
            "does not match the contents: the file is corrupt or truncated (a changed byte \
             or a partial copy), or was written by an older unispine without a checksum",
        )
    };
    let split = bytes.len().checked_sub(8).ok_or_else(corrupt)?;
    let (body, sum) = bytes.split_at(split);
    let h = crate::fingerprint::Words::default().bytes(body).finish();
    if h.to_le_bytes() != sum {
        return Err(corrupt());
    }
    Ok(body)
}

/// Split the bytes of the framed file `path` ([`frame_header`]) into its parsed header and
/// the payload; a wrong magic (`what` names the expected kind of file), a length past the end
/// or a header that is not the JSON of `H` is an error naming the file and field.
pub fn read_frame<'a, H: serde::de::DeserializeOwned>(
    path: &Path,
    bytes: &'a [u8],
    magic: &[u8],
    what: &str,
) -> Result<(H, &'a [u8])> {
    let bad = |field: &str, msg: String| Error::format(path, field, msg);
    if !bytes.starts_with(magic) {
        return Err(bad("magic", format!("not {what}")));
    }
    let bytes = unseal(path, bytes)?;
    let rest = &bytes[magic.len()..];
    if rest.len() < 8 {
        return Err(bad("header", "file ends inside the header length".into()));
    }
    let hl = u64::from_le_bytes(rest[..8].try_into().expect("8 bytes"));
    let rest = &rest[8..];
    let hl = usize::try_from(hl)
        .ok()
        .filter(|&l| l <= rest.len())
        .ok_or_else(|| bad("header", format!("length {hl} exceeds the file")))?;
    let h = serde_json::from_slice(&rest[..hl])
        .map_err(|e| bad("header", format!("not valid JSON: {e}")))?;
    Ok((h, &rest[hl..]))
}

/// Largest plan or JSON record the harness reads (plans, `cell.json`, `metrics.json`,
/// `config.json`, `data-args.json`): 16 MiB.
pub const MAX_TEXT_BYTES: u64 = 16 << 20;

/// Largest checkpoint read: 64 GiB (a device or FIFO is refused whatever the size).
pub const MAX_CHECKPOINT_BYTES: u64 = 64 << 30;

/// Largest `log.csv` read for charts: 256 MiB (a 20-million-iteration log).
pub const MAX_LOG_BYTES: u64 = 256 << 20;

/// Open `path` for reading only if it is a regular file (symlinks followed). The file is opened
/// without blocking (a FIFO swapped in between the check and the open is refused, not waited
/// on) and checked again on the open handle, so a device, FIFO or folder is refused before any
/// byte is read.
pub fn open_regular(path: &Path) -> Result<std::fs::File> {
    let refuse = |what: &str| {
        Error::format(
            path,
            "file",
            format!("is {what}, not a regular file: refused"),
        )
    };
    let meta = std::fs::metadata(path).map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        return Err(refuse(file_kind(&meta)));
    }
    let mut opts = std::fs::OpenOptions::new();
    opts.read(true);
    #[cfg(unix)]
    {
        use std::os::unix::fs::OpenOptionsExt;
        opts.custom_flags(libc::O_NONBLOCK);
    }
    let f = opts.open(path).map_err(|e| Error::io(path, e))?;
    let meta = f.metadata().map_err(|e| Error::io(path, e))?;
    if !meta.is_file() {
        return Err(refuse(file_kind(&meta)));
    }
    Ok(f)
}

fn file_kind(meta: &std::fs::Metadata) -> &'static str {
    #[cfg(unix)]
    {
        use std::os::unix::fs::FileTypeExt;
        let t = meta.file_type();
        if t.is_fifo() {
            return "a FIFO";
        }
        if t.is_char_device() || t.is_block_device() {
            return "a device";
        }
        if t.is_socket() {
            return "a socket";
        }
    }
    if meta.is_dir() {
        "a folder"
    } else {
        "not a regular file"
    }
}

/// Read a regular file of at most `limit` bytes ([`open_regular`]); a larger file is an error
/// naming the limit, found without reading more than `limit + 1` bytes.
pub fn read_bounded(path: &Path, limit: u64) -> Result<Vec<u8>> {
    use std::io::Read;
    let f = open_regular(path)?;
    let mut buf = Vec::new();
    f.take(limit + 1)
        .read_to_end(&mut buf)
        .map_err(|e| Error::io(path, e))?;
    if buf.len() as u64 > limit {
        return Err(Error::format(
            path,
            "file",
            format!("is larger than the {limit} bytes allowed here"),
        ));
    }
    Ok(buf)
}

/// [`read_bounded`] as UTF-8 text.
pub fn read_text_bounded(path: &Path, limit: u64) -> Result<String> {
    String::from_utf8(read_bounded(path, limit)?)
        .map_err(|_| Error::format(path, "file", "is not UTF-8 text"))
}

/// `root.join(rel)` after checking that `rel` is relative, made of plain names only (no `..`,
/// no root, no `.`), and that no part of it that already exists below `root` is a symbolic link,
/// so that writing or removing the result can never reach outside `root`.
pub fn path_under(root: &Path, rel: &Path) -> Result<PathBuf> {
    use std::path::Component;
    let mut p = root.to_path_buf();
    for c in rel.components() {
        let Component::Normal(name) = c else {
            return Err(Error::invalid(
                "path",
                format!(
                    "{} would leave the output folder {}",
                    rel.display(),
                    root.display()
                ),
            ));
        };
        p.push(name);
        if let Ok(m) = std::fs::symlink_metadata(&p) {
            if m.file_type().is_symlink() {
                return Err(Error::invalid(
                    "path",
                    format!(
                        "{} is a symbolic link inside the output folder: refused (nothing is \
                         written or removed through a link)",
                        p.display()
                    ),
                ));
            }
        }
    }
    Ok(p)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn atomic_write_replaces_and_leaves_no_temporary() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("a.json");
        write_atomic(&p, b"one").unwrap();
        write_atomic(&p, b"two").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        assert!(!temp_path(&p).exists());
    }

    #[test]
    fn failed_write_keeps_the_old_file() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("a.json");
        write_atomic(&p, b"old").unwrap();
        // The temporary name is taken by a folder: creating it fails.
        std::fs::create_dir(temp_path(&p)).unwrap();
        assert!(write_atomic(&p, b"new").is_err());
        assert_eq!(std::fs::read(&p).unwrap(), b"old");
    }

    #[test]
    fn an_input_among_the_outputs_is_refused() {
        let d = tempfile::tempdir().unwrap();
        let v = d.path().join("volume.npy");
        std::fs::write(&v, b"x").unwrap();
        let dotted = d.path().join(".").join("volume.npy");
        let e = check_not_output("--volume", &dotted, std::slice::from_ref(&v)).unwrap_err();
        assert!(e.to_string().contains("--volume"), "{e}");
        assert!(check_not_output("--volume", &v, &[d.path().join("train.npy")]).is_ok());
    }

    #[test]
    fn bounded_reads_refuse_devices_fifos_folders_and_large_files() {
        let d = tempfile::tempdir().unwrap();
        let p = d.path().join("plan.toml");
        std::fs::write(&p, b"0123456789").unwrap();
        assert_eq!(read_bounded(&p, 10).unwrap(), b"0123456789");
        let e = read_bounded(&p, 9).unwrap_err().to_string();
        assert!(e.contains("larger than the 9 bytes"), "{e}");
        for (dev, what) in [("/dev/zero", "a device"), ("/dev/urandom", "a device")] {
            let e = read_bounded(Path::new(dev), 1 << 20)
                .unwrap_err()
                .to_string();
            assert!(e.contains(what) && e.contains(dev), "{e}");
        }
        let e = read_bounded(d.path(), 10).unwrap_err().to_string();
        assert!(e.contains("a folder"), "{e}");
        let fifo = d.path().join("fifo");
        let c = std::ffi::CString::new(fifo.to_str().unwrap()).unwrap();
        // SAFETY: a valid NUL-terminated path.
        assert_eq!(unsafe { libc::mkfifo(c.as_ptr(), 0o600) }, 0);
        // Returns at once (no writer is ever attached): refused, not waited on.
        let e = read_bounded(&fifo, 10).unwrap_err().to_string();
        assert!(e.contains("a FIFO"), "{e}");
        // A link to a device is followed and refused too.
        let link = d.path().join("train.npy");
        std::os::unix::fs::symlink("/dev/zero", &link).unwrap();
        assert!(read_bounded(&link, 10)
            .unwrap_err()
            .to_string()
            .contains("a device"));
    }

    #[test]
    fn paths_under_the_root_refuse_escapes_and_links() {
        let d = tempfile::tempdir().unwrap();
        let root = d.path().join("out");
        std::fs::create_dir_all(root.join("runs")).unwrap();
        assert_eq!(
            path_under(&root, Path::new("runs/ct/m/seed0")).unwrap(),
            root.join("runs/ct/m/seed0")
        );
        for bad in ["../x", "/etc", "runs/../../x", "./runs", ""] {
            let r = path_under(&root, Path::new(bad));
            if bad.is_empty() {
                assert_eq!(r.unwrap(), root);
            } else {
                assert!(r.is_err(), "{bad}");
            }
        }
        let outside = d.path().join("outside");
        std::fs::create_dir(&outside).unwrap();
        std::os::unix::fs::symlink(&outside, root.join("runs/ct")).unwrap();
        let e = path_under(&root, Path::new("runs/ct/m"))
            .unwrap_err()
            .to_string();
        assert!(e.contains("symbolic link"), "{e}");
    }
}
