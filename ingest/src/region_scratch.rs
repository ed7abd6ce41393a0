//! Scratch files of region metadata: what a pass has found but cannot write into the store
//! yet, on disk rather than in memory.
//!
//! - **Cell records**: rows of min/max cells that other passes still fold into: a column's
//!   (the next columns reach the same rows), a partition's (`finalize` merges the partitions'
//!   rows). Records are kept by chunk of rows ([`CHUNK_ROWS`]), and a chunk is assembled
//!   whole once every column or partition has passed it.
//! - **Histogram records**: blocks of brick histograms, binned when the channels' ranges are
//!   known, at the end of the pass.
//!
//! Each record is one postcard value; a record's place is its offset and length in its file.

use std::collections::BTreeMap;
use std::fs::File;
use std::io::{BufWriter, Write};
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::regions::{CHUNK_ROWS, CellGrid, HistogramBlock};
use crate::sample_format::Sample;

/// Where a record lies in its file.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Record {
    /// Its first byte.
    pub offset: u64,
    /// Its length in bytes.
    pub len: u64,
}

/// One level's records that a partition leaves for `finalize`, beside its hand-over file.
#[derive(Clone, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct LevelRecords {
    /// Rows of cells: `(chunk of rows, record)`, in the order written.
    pub cells: Vec<(u64, Record)>,
    /// Blocks of brick histograms.
    pub histograms: Vec<Record>,
}

/// A scratch file of region metadata that cannot be written or read back.
#[derive(Debug, thiserror::Error)]
#[error("{}: cannot {what} this scratch file of region metadata", path.display())]
pub struct ScratchError {
    /// The file.
    pub path: PathBuf,
    /// What failed (`create`, `write`, `read`, `open`, `remove`).
    pub what: &'static str,
    /// Why.
    #[source]
    pub source: ScratchCause,
}

/// Why a scratch file cannot be used: the file system, or a record that does not encode or
/// decode.
#[derive(Debug, thiserror::Error)]
pub enum ScratchCause {
    /// What the file system said.
    #[error(transparent)]
    Io(#[from] std::io::Error),
    /// What postcard said.
    #[error(transparent)]
    Record(#[from] postcard::Error),
}

fn scratch_error<E: Into<ScratchCause>>(
    path: &Path,
    what: &'static str,
) -> impl FnOnce(E) -> ScratchError + use<E> {
    let path = path.to_path_buf();
    move |source| ScratchError {
        path,
        what,
        source: source.into(),
    }
}

/// Reads the record at `record` of `file` (named `path` in messages).
fn read_record<R: serde::de::DeserializeOwned>(
    file: &File,
    path: &Path,
    record: Record,
) -> Result<R, ScratchError> {
    let mut bytes = vec![0; record.len as usize];
    file.read_exact_at(&mut bytes, record.offset)
        .map_err(scratch_error(path, "read"))?;
    postcard::from_bytes(&bytes).map_err(scratch_error(path, "read"))
}

/// An append-only scratch file of records.
pub struct Scratch {
    path: PathBuf,
    file: BufWriter<File>,
    /// Bytes written so far.
    len: u64,
}

impl Scratch {
    /// Creates (or empties) the file at `path`, and its folder.
    ///
    /// # Errors
    /// When the folder or the file cannot be created.
    pub fn create(path: PathBuf) -> Result<Self, ScratchError> {
        let file = path
            .parent()
            .map_or(Ok(()), std::fs::create_dir_all)
            .and_then(|()| {
                File::options()
                    .read(true)
                    .write(true)
                    .create(true)
                    .truncate(true)
                    .open(&path)
            })
            .map_err(scratch_error(&path, "create"))?;
        Ok(Self {
            path,
            file: BufWriter::new(file),
            len: 0,
        })
    }

    /// Appends a value; returns its record.
    ///
    /// # Errors
    /// When the file cannot be written.
    pub fn append(&mut self, value: &impl Serialize) -> Result<Record, ScratchError> {
        let bytes = postcard::to_stdvec(value).map_err(scratch_error(&self.path, "write"))?;
        self.file
            .write_all(&bytes)
            .map_err(scratch_error(&self.path, "write"))?;
        let record = Record {
            offset: self.len,
            len: bytes.len() as u64,
        };
        self.len += record.len;
        Ok(record)
    }

    /// Reads back a value it holds.
    ///
    /// # Errors
    /// When the file cannot be read or the record does not decode.
    pub fn read<R: serde::de::DeserializeOwned>(
        &mut self,
        record: Record,
    ) -> Result<R, ScratchError> {
        self.flush()?;
        read_record(self.file.get_ref(), &self.path, record)
    }

    /// Writes what is buffered to the file.
    ///
    /// # Errors
    /// When the file cannot be written.
    pub fn flush(&mut self) -> Result<(), ScratchError> {
        self.file
            .flush()
            .map_err(scratch_error(&self.path, "write"))
    }

    /// Removes the file, and its folder once empty.
    ///
    /// # Errors
    /// When the file cannot be removed.
    pub fn remove(self) -> Result<(), ScratchError> {
        let Self { path, file, .. } = self;
        drop(file);
        std::fs::remove_file(&path).map_err(scratch_error(&path, "remove"))?;
        if let Some(folder) = path.parent() {
            // The last file's removal empties it.
            let _ = std::fs::remove_dir(folder);
        }
        Ok(())
    }
}

/// A pass's own scratch file, and the files of other passes (partitions) whose records it
/// adopted, read where they lie.
struct RecordFiles {
    own: Scratch,
    /// Partitions' record files: path (for messages) and file.
    adopted: Vec<(PathBuf, File)>,
}

/// Which file of a [`RecordFiles`] a record is in: 0 for its own, `i + 1` for adopted file `i`.
type FileIndex = usize;

impl RecordFiles {
    fn create(path: PathBuf) -> Result<Self, ScratchError> {
        Ok(Self {
            own: Scratch::create(path)?,
            adopted: Vec::new(),
        })
    }

    /// Opens another pass's file at `path`; returns its index.
    fn adopt(&mut self, path: &Path) -> Result<FileIndex, ScratchError> {
        let file = File::open(path).map_err(scratch_error(path, "open"))?;
        self.adopted.push((path.to_path_buf(), file));
        Ok(self.adopted.len())
    }

    fn read<R: serde::de::DeserializeOwned>(
        &mut self,
        (file, record): (FileIndex, Record),
    ) -> Result<R, ScratchError> {
        if file == 0 {
            self.own.read(record)
        } else {
            let (path, file) = &self.adopted[file - 1];
            read_record(file, path, record)
        }
    }
}

/// Rows of cells waiting for every column or partition to pass them: this pass's own records
/// and those of partitions' files it adopted, by chunk of rows.
pub struct CellRecords {
    files: RecordFiles,
    /// Each chunk's records.
    chunks: BTreeMap<u64, Vec<(FileIndex, Record)>>,
    /// Its own records in the order written, for a partition's hand-over.
    written: Vec<(u64, Record)>,
    /// The first row not yet assembled.
    pub next: u64,
}

impl CellRecords {
    /// Records in a new scratch file at `path`.
    ///
    /// # Errors
    /// When the file cannot be created.
    pub fn create(path: PathBuf) -> Result<Self, ScratchError> {
        Ok(Self {
            files: RecordFiles::create(path)?,
            chunks: BTreeMap::new(),
            written: Vec::new(),
            next: 0,
        })
    }

    /// Appends a block of cells (a column's or a partition's rows), split by chunk of rows.
    ///
    /// # Errors
    /// When the file cannot be written.
    pub fn spill<T: Sample>(&mut self, block: &CellGrid<T>) -> Result<(), ScratchError> {
        let rows = block.rows();
        let mut start = rows.start;
        while start < rows.end {
            let chunk = start / CHUNK_ROWS;
            let end = ((chunk + 1) * CHUNK_ROWS).min(rows.end);
            let record = self.files.own.append(&block.rows_of(start..end))?;
            self.chunks.entry(chunk).or_default().push((0, record));
            self.written.push((chunk, record));
            start = end;
        }
        Ok(())
    }

    /// Takes in the records of another pass's file at `path` (a partition's).
    ///
    /// # Errors
    /// When the file cannot be opened.
    pub fn adopt(&mut self, path: &Path, records: &[(u64, Record)]) -> Result<(), ScratchError> {
        if records.is_empty() {
            return Ok(());
        }
        let file = self.files.adopt(path)?;
        for &(chunk, record) in records {
            self.chunks.entry(chunk).or_default().push((file, record));
        }
        Ok(())
    }

    /// Folds every record of chunk `chunk` into `rows`, and forgets them.
    ///
    /// # Errors
    /// When a file cannot be read or a record does not decode.
    pub fn take_chunk<T: Sample>(
        &mut self,
        chunk: u64,
        rows: &mut CellGrid<T>,
    ) -> Result<(), ScratchError> {
        for record in self.chunks.remove(&chunk).unwrap_or_default() {
            let block: CellGrid<T> = self.files.read(record)?;
            rows.merge(&block);
        }
        Ok(())
    }

    /// Its own records, in the order written, with the file flushed: what a partition hands
    /// over.
    ///
    /// # Errors
    /// When the file cannot be written.
    pub fn into_records(mut self) -> Result<Vec<(u64, Record)>, ScratchError> {
        self.files.own.flush()?;
        Ok(self.written)
    }

    /// Removes its own file.
    ///
    /// # Errors
    /// When the file cannot be removed.
    pub fn remove(self) -> Result<(), ScratchError> {
        self.files.own.remove()
    }
}

/// Blocks of brick histograms waiting to be binned: its own and those of partitions' files it
/// adopted, read where they lie.
pub struct HistogramRecords {
    files: RecordFiles,
    blocks: Vec<(FileIndex, Record)>,
}

impl HistogramRecords {
    /// Records in a new scratch file at `path`.
    ///
    /// # Errors
    /// When the file cannot be created.
    pub fn create(path: PathBuf) -> Result<Self, ScratchError> {
        Ok(Self {
            files: RecordFiles::create(path)?,
            blocks: Vec::new(),
        })
    }

    /// Appends a block.
    ///
    /// # Errors
    /// When the file cannot be written.
    pub fn push(&mut self, block: &HistogramBlock) -> Result<(), ScratchError> {
        let record = self.files.own.append(block)?;
        self.blocks.push((0, record));
        Ok(())
    }

    /// Takes in the blocks of another pass's file at `path` (a partition's).
    ///
    /// # Errors
    /// When the file cannot be opened.
    pub fn adopt(&mut self, path: &Path, records: &[Record]) -> Result<(), ScratchError> {
        if records.is_empty() {
            return Ok(());
        }
        let file = self.files.adopt(path)?;
        self.blocks.extend(records.iter().map(|&r| (file, r)));
        Ok(())
    }

    /// Reads the blocks back one at a time, in the order pushed or adopted.
    ///
    /// # Errors
    /// When a file cannot be read, a record does not decode, or `each` fails.
    pub fn for_each<E: From<ScratchError>>(
        &mut self,
        mut each: impl FnMut(HistogramBlock) -> Result<(), E>,
    ) -> Result<(), E> {
        for record in std::mem::take(&mut self.blocks) {
            each(self.files.read(record)?)?;
        }
        Ok(())
    }

    /// Its own records, in the order pushed, with the file flushed: what a partition hands
    /// over.
    ///
    /// # Errors
    /// When the file cannot be written.
    pub fn into_records(mut self) -> Result<Vec<Record>, ScratchError> {
        self.files.own.flush()?;
        Ok(self.blocks.into_iter().map(|(_, r)| r).collect())
    }

    /// Removes its own file.
    ///
    /// # Errors
    /// When the file cannot be removed.
    pub fn remove(self) -> Result<(), ScratchError> {
        self.files.own.remove()
    }
}
