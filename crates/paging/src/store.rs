//! Where bricks go when they leave the pool: a backing file by positioned I/O, or memory.
//!
//! **Positioned I/O, not memory mapping.** Mapping the backing file would let the kernel
//! page for us, but every safe Rust mapping API is `unsafe` to create (the file may change
//! under the mapping), and the workspace forbids `unsafe`. Positioned reads and writes
//! (`pread`/`pwrite`: `FileExt::read_exact_at`, `write_all_at`) need none, take no file
//! cursor (threads share the file without a lock), move one brick per call, and let the
//! pager decide what stays resident, which is the point of Bernabei's design. The
//! operating system's page cache still sits under the file, so a brick written and read
//! again soon costs a copy, not a disk access (`cargo xtask bench-paging` measures both).

use std::fmt::Debug;
use std::fs::File;
use std::io;
use std::path::{Path, PathBuf};

use crate::error::PagingError;

/// A place bricks are written to and read back from, by number, as bytes. Every brick of
/// one store has the same size (the pager's brick length times its element's size), so
/// brick `b` of a file lives at byte `b` times that size.
pub trait BrickStore: Send + Sync + Debug {
    /// Reads brick `brick` into `out` (the brick's bytes). Only bricks written before are
    /// read.
    fn read(&self, brick: usize, out: &mut [u8]) -> io::Result<()>;
    /// Writes brick `brick` (its bytes).
    fn write(&self, brick: usize, data: &[u8]) -> io::Result<()>;
    /// What the store is, for messages (a file's path).
    fn describe(&self) -> String;
}

/// Bricks in an unnamed temporary file (removed by the operating system when the store
/// is dropped, or the process ends, however it ends), brick `b` at byte `b` times the
/// brick's size.
#[derive(Debug)]
pub struct FileStore {
    file: File,
    dir: PathBuf,
}

impl FileStore {
    /// A new backing file in `dir`.
    pub fn create_in(dir: &Path) -> Result<Self, PagingError> {
        let file = tempfile::tempfile_in(dir).map_err(|source| PagingError::Create {
            dir: dir.to_owned(),
            source,
        })?;
        Ok(Self {
            file,
            dir: dir.to_owned(),
        })
    }

    /// A new backing file in the system's temporary folder (`TMPDIR`).
    pub fn create() -> Result<Self, PagingError> {
        Self::create_in(&std::env::temp_dir())
    }
}

impl BrickStore for FileStore {
    fn read(&self, brick: usize, out: &mut [u8]) -> io::Result<()> {
        read_at(&self.file, out, brick as u64 * out.len() as u64)
    }

    fn write(&self, brick: usize, data: &[u8]) -> io::Result<()> {
        write_at(&self.file, data, brick as u64 * data.len() as u64)
    }

    fn describe(&self) -> String {
        format!("a backing file in {}", self.dir.display())
    }
}

#[cfg(unix)]
fn read_at(file: &File, buf: &mut [u8], offset: u64) -> io::Result<()> {
    std::os::unix::fs::FileExt::read_exact_at(file, buf, offset)
}

#[cfg(unix)]
fn write_at(file: &File, buf: &[u8], offset: u64) -> io::Result<()> {
    std::os::unix::fs::FileExt::write_all_at(file, buf, offset)
}

#[cfg(windows)]
fn read_at(file: &File, mut buf: &mut [u8], mut offset: u64) -> io::Result<()> {
    use std::os::windows::fs::FileExt;
    while !buf.is_empty() {
        match file.seek_read(buf, offset)? {
            0 => return Err(io::ErrorKind::UnexpectedEof.into()),
            n => {
                buf = &mut buf[n..];
                offset += n as u64;
            }
        }
    }
    Ok(())
}

#[cfg(windows)]
fn write_at(file: &File, mut buf: &[u8], mut offset: u64) -> io::Result<()> {
    use std::os::windows::fs::FileExt;
    while !buf.is_empty() {
        match file.seek_write(buf, offset)? {
            0 => return Err(io::ErrorKind::WriteZero.into()),
            n => {
                buf = &buf[n..];
                offset += n as u64;
            }
        }
    }
    Ok(())
}

/// Bricks kept in memory: for tests, and for fields whose budget holds them anyway.
#[derive(Debug, Default)]
pub struct MemoryStore {
    bricks: parking_lot::Mutex<std::collections::HashMap<usize, Vec<u8>>>,
}

impl BrickStore for MemoryStore {
    fn read(&self, brick: usize, out: &mut [u8]) -> io::Result<()> {
        let bricks = self.bricks.lock();
        let data = bricks
            .get(&brick)
            .ok_or_else(|| io::Error::new(io::ErrorKind::NotFound, "never written"))?;
        out.copy_from_slice(data);
        Ok(())
    }

    fn write(&self, brick: usize, data: &[u8]) -> io::Result<()> {
        self.bricks.lock().insert(brick, data.to_vec());
        Ok(())
    }

    fn describe(&self) -> String {
        "memory".into()
    }
}
