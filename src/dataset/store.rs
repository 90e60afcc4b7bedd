//! Dataset folders: `dataset.json`, `train.npy`, `test.npy`, `volume.npy`, PNG previews
//! (interface; not written yet).

use std::path::Path;

use super::Dataset;
use crate::error::{Error, Result};

/// Write `ds` into the folder `dir` (created if missing).
pub fn save(_ds: &Dataset, dir: &Path) -> Result<()> {
    Err(Error::format(
        dir,
        "dataset",
        "dataset storage is not implemented yet",
    ))
}

/// Read a dataset folder written by [`save`].
pub fn load(dir: &Path) -> Result<Dataset> {
    Err(Error::format(
        dir,
        "dataset",
        "dataset storage is not implemented yet",
    ))
}
