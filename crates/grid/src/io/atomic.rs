//! Output files that appear whole or not at all.
//!
//! A writer that fails half way (a full disk, a quota, a signal) must not leave a
//! truncated file behind, nor replace a good older one with it; and a small file whose
//! bytes sat in a buffer when the disk filled must not be reported as written (a
//! `BufWriter` dropped without `flush` swallows that error: a 0-byte PNG and "rendered").
//! So every output of lucent is written to a partial file beside its target
//! (`.NAME.lucent-partial`, in the same folder so that the rename stays on one file
//! system), flushed, `fsync`ed, and renamed over the target only when complete; on any
//! error the partial file is removed and the target is untouched.
//!
//! A process that must end at once (a second Ctrl-C) calls [`remove_partial_files`] first,
//! so that no partial file outlives it either.

use std::fs::{self, File, OpenOptions};
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

/// Partial files being written by this process, for [`remove_partial_files`].
static PENDING: Mutex<Vec<PathBuf>> = Mutex::new(Vec::new());

fn pending() -> std::sync::MutexGuard<'static, Vec<PathBuf>> {
    PENDING
        .lock()
        .unwrap_or_else(std::sync::PoisonError::into_inner)
}

/// The partial file beside `target` that the ranks of a decomposition fill together
/// (`dir/.NAME.lucent-partial`): deterministic, so that every rank opens the same file for
/// its positioned writes before one of them [`publish`]es it. ([`AtomicFile`] adds the
/// process and a counter to the name, so that two writers in one folder never meet.)
pub fn partial_path(target: &Path) -> PathBuf {
    partial_named(target, "")
}

fn partial_named(target: &Path, tag: &str) -> PathBuf {
    let name = target
        .file_name()
        .map_or_else(|| "output".into(), |n| n.to_string_lossy().into_owned());
    target.with_file_name(format!(".{name}{tag}.lucent-partial"))
}

/// Removes every partial file this process is writing: for a process about to end
/// without unwinding (`std::process::exit` from a signal handler).
pub fn remove_partial_files() {
    for path in pending().drain(..) {
        let _ = fs::remove_file(path);
    }
}

/// An output file written whole or not at all: [`AtomicFile::create`], write through
/// [`Write`], then [`AtomicFile::commit`]. Dropped without `commit` (an error, a panic),
/// it removes its partial file and leaves the target as it was.
#[derive(Debug)]
pub struct AtomicFile {
    target: PathBuf,
    partial: PathBuf,
    writer: Option<BufWriter<File>>,
    /// Renamed over the target: nothing left to clean up.
    published: bool,
}

impl AtomicFile {
    /// Starts writing `target` (through a partial file of its own beside it).
    ///
    /// # Errors
    /// The partial file cannot be created (no such folder, no permission).
    pub fn create(target: impl AsRef<Path>) -> io::Result<Self> {
        use std::sync::atomic::{AtomicU64, Ordering};
        static SERIAL: AtomicU64 = AtomicU64::new(0);
        let target = target.as_ref().to_owned();
        let tag = format!(
            ".{}.{}",
            std::process::id(),
            SERIAL.fetch_add(1, Ordering::Relaxed)
        );
        let partial = partial_named(&target, &tag);
        let file = OpenOptions::new()
            .write(true)
            .create(true)
            .truncate(true)
            .open(&partial)?;
        pending().push(partial.clone());
        Ok(Self {
            target,
            partial,
            writer: Some(BufWriter::with_capacity(1 << 20, file)),
            published: false,
        })
    }

    /// The file being written, for positioned writes (flush [`Write`]'s buffer first).
    pub fn file(&mut self) -> io::Result<&File> {
        let writer = self.writer.as_mut().ok_or_else(closed)?;
        writer.flush()?;
        Ok(writer.get_ref())
    }

    /// Flushes, `fsync`s and renames the partial file over the target: the target is
    /// now the complete file. The target keeps its permissions where it existed.
    ///
    /// # Errors
    /// Any write error the buffer still held, `fsync`, the rename; the partial file is
    /// removed and the target untouched.
    pub fn commit(mut self) -> io::Result<()> {
        let writer = self.writer.take().ok_or_else(closed)?;
        let file = writer
            .into_inner()
            .map_err(io::IntoInnerError::into_error)?;
        file.sync_all()?;
        if let Ok(meta) = fs::metadata(&self.target) {
            file.set_permissions(meta.permissions())?;
        } else {
            set_default_permissions(&file)?;
        }
        drop(file);
        publish(&self.partial, &self.target)?;
        self.published = true;
        pending().retain(|p| p != &self.partial);
        Ok(())
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.writer.as_mut().ok_or_else(closed)?.write(buf)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.writer.as_mut().ok_or_else(closed)?.flush()
    }
}

impl Drop for AtomicFile {
    fn drop(&mut self) {
        // Not committed (an error in the body, or in `commit` itself): the partial file
        // goes, the target stays as it was. The buffer is dropped first (its flush may
        // write more, into the file about to go).
        if !self.published {
            drop(self.writer.take());
            let _ = fs::remove_file(&self.partial);
            pending().retain(|p| p != &self.partial);
        }
    }
}

fn closed() -> io::Error {
    io::Error::other("the output file was already committed")
}

/// A new output's permissions: rw-r--r-- (what `File::create` gives under the usual
/// umask 022; the partial file was created private).
fn set_default_permissions(file: &File) -> io::Result<()> {
    #[cfg(unix)]
    {
        use std::os::unix::fs::PermissionsExt;
        file.set_permissions(fs::Permissions::from_mode(0o644))
    }
    #[cfg(not(unix))]
    {
        let _ = file;
        Ok(())
    }
}

/// Renames the complete file `partial` over `target` and `fsync`s the folder, so that
/// the rename itself survives a crash. For partial files filled by several writers (the
/// ranks of a decomposition, each through [`partial_path`]): call once, after all have
/// finished and `fsync`ed.
///
/// # Errors
/// The rename (the partial file is then removed).
pub fn publish(partial: &Path, target: &Path) -> io::Result<()> {
    if let Err(e) = fs::rename(partial, target) {
        let _ = fs::remove_file(partial);
        return Err(e);
    }
    #[cfg(unix)]
    if let Some(folder) = target.parent() {
        let folder = if folder.as_os_str().is_empty() {
            Path::new(".")
        } else {
            folder
        };
        // Best effort: some file systems refuse to fsync a folder.
        let _ = File::open(folder).and_then(|f| f.sync_all());
    }
    Ok(())
}

/// Writes `target` whole or not at all with `body`, which writes the bytes.
///
/// # Errors
/// What `body` returns, and I/O (creating, flushing, `fsync`, renaming); the target is
/// then untouched and no partial file remains.
pub fn write_with<E: From<io::Error>>(
    target: impl AsRef<Path>,
    body: impl FnOnce(&mut AtomicFile) -> Result<(), E>,
) -> Result<(), E> {
    let mut file = AtomicFile::create(target)?;
    body(&mut file)?;
    file.commit()?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_failed_write_leaves_the_old_file_and_no_partial_one() {
        let dir = std::env::temp_dir().join(format!("lucent-atomic-{}", std::process::id()));
        fs::create_dir_all(&dir).unwrap();
        let target = dir.join("out.bin");
        fs::write(&target, b"old").unwrap();
        let failed: io::Result<()> = write_with(&target, |f| {
            f.write_all(b"new, half")?;
            Err(io::Error::other("disk full"))
        });
        assert!(failed.is_err());
        assert_eq!(fs::read(&target).unwrap(), b"old");
        let names = || {
            let mut n: Vec<_> = fs::read_dir(&dir)
                .unwrap()
                .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
                .collect();
            n.sort();
            n
        };
        assert_eq!(names(), ["out.bin"]);
        write_with(&target, |f| f.write_all(b"new")).unwrap();
        assert_eq!(fs::read(&target).unwrap(), b"new");
        assert_eq!(names(), ["out.bin"]);
        fs::remove_dir_all(&dir).unwrap();
    }
}
