//! The output policy of fmaps: what a path named as an output gets.
//!
//! - A regular file, or a path that does not exist yet, is written
//!   atomically: the content goes to a temporary file beside it (same
//!   folder, so the same file system), synced, and renamed over it only once
//!   complete. A failure (full disk, unwritable folder, an error while
//!   producing the content) leaves the previous file untouched and no
//!   temporary behind.
//! - A symbolic link is followed: the file it points to is written (by the
//!   rule above, or the next one), and the link stays.
//! - A character or block device, a FIFO or a socket (or a link to one) is
//!   opened and written through: never removed, never renamed over. A
//!   failed write (`ENOSPC` on `/dev/full`) is an error naming the path.
//! - `-` is standard output.
//!
//! [`Outputs`] commits several outputs of one command together: every
//! content is produced first, then the written-through ones are written,
//! then the regular files renamed into place, so that a failure while
//! producing any of them leaves every output as it was.

use std::fs;
use std::io::{self, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

/// Distinguishes the temporary files of one process.
static NEXT: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// How [`write_atomically`] and [`Outputs`] write a path.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum OutputTarget {
    /// A regular file or a new path (after following links): written to a
    /// temporary sibling, then renamed to this path.
    File(PathBuf),
    /// A device, FIFO or socket (or a link to one): opened and written
    /// through.
    WriteThrough(PathBuf),
    /// `-`: standard output.
    Stdout,
}

/// Links followed at most (as the kernel's `ELOOP` limit).
const MAX_LINKS: usize = 40;

/// Where an output named `path` goes (see the module docs): symbolic links
/// are followed, so a link is never replaced by a file.
///
/// Errors: a loop of links, an existing path that is a directory.
pub fn output_target(path: &Path) -> io::Result<OutputTarget> {
    if path.as_os_str() == "-" {
        return Ok(OutputTarget::Stdout);
    }
    // The kernel follows the links (also those of /proc, whose targets
    // are not paths, as /dev/stdout's).
    match fs::metadata(path) {
        Ok(m) if m.is_file() => return Ok(OutputTarget::File(fs::canonicalize(path)?)),
        Ok(m) if m.is_dir() => {
            return Err(io::Error::new(
                io::ErrorKind::IsADirectory,
                "is a directory, not a file",
            ));
        }
        // Devices, FIFOs, sockets.
        Ok(_) => return Ok(OutputTarget::WriteThrough(path.to_path_buf())),
        Err(e) if e.kind() == io::ErrorKind::NotFound => {}
        Err(e) => return Err(e),
    }
    // A new path, or a dangling link: the file the links lead to.
    let mut p = path.to_path_buf();
    for _ in 0..MAX_LINKS {
        match fs::symlink_metadata(&p) {
            Ok(m) if m.file_type().is_symlink() => {
                let to = fs::read_link(&p)?;
                p = match p.parent() {
                    Some(dir) if to.is_relative() => dir.join(to),
                    _ => to,
                };
            }
            _ => return Ok(OutputTarget::File(p)),
        }
    }
    Err(io::Error::other(format!(
        "more than {MAX_LINKS} symbolic links to follow"
    )))
}

/// The temporary sibling of `path`: a hidden file in the same folder.
pub fn temporary_path(path: &Path) -> PathBuf {
    let name = path
        .file_name()
        .map_or_else(|| "output".into(), |n| n.to_string_lossy().into_owned());
    let k = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    path.with_file_name(format!(".{name}.{}.{k}.tmp", std::process::id()))
}

/// A temporary file for content bound for a written-through target (whose
/// folder, e.g. `/dev`, may not take files): in the system's temporary
/// folder.
fn spool_path() -> PathBuf {
    let k = NEXT.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
    std::env::temp_dir().join(format!(".fmaps-output.{}.{k}.tmp", std::process::id()))
}

/// Writes the output `path` through `write` (given a buffered writer), by
/// the policy of the module docs: a regular file or a new path atomically
/// (a temporary sibling, flushed and synced, renamed over it: on any error
/// the temporary is removed and the file is as it was), a device, FIFO or
/// socket written through, `-` to standard output, links followed.
pub fn write_atomically(
    path: &Path,
    write: impl FnOnce(&mut dyn Write) -> io::Result<()>,
) -> io::Result<()> {
    match output_target(path)? {
        OutputTarget::File(target) => {
            let tmp = temporary_path(&target);
            let result = (|| {
                let mut w = BufWriter::new(fs::File::create(&tmp)?);
                write(&mut w)?;
                let file = w.into_inner().map_err(|e| e.into_error())?;
                file.sync_all()?;
                fs::rename(&tmp, &target)
            })();
            if result.is_err() {
                let _ = fs::remove_file(&tmp);
            }
            result
        }
        OutputTarget::WriteThrough(target) => {
            let mut w = BufWriter::new(open_through(&target)?);
            write(&mut w)?;
            w.flush()
        }
        OutputTarget::Stdout => {
            let stdout = io::stdout();
            let mut w = BufWriter::new(stdout.lock());
            write(&mut w)?;
            w.flush()
        }
    }
}

/// Opens a device, FIFO or socket for writing, without creating or
/// truncating anything.
fn open_through(path: &Path) -> io::Result<fs::File> {
    fs::OpenOptions::new().write(true).open(path)
}

/// One staged output of [`Outputs`].
#[derive(Debug)]
struct Staged {
    /// Where the content was written.
    tmp: PathBuf,
    /// Where it goes.
    target: OutputTarget,
    /// The path as the caller named it (for messages).
    named: PathBuf,
}

/// Several outputs of one command, committed together: [`stage`] writes
/// each content to a temporary file; [`commit`] writes the
/// written-through targets (devices, FIFOs, standard output), then renames
/// the regular files into place. Dropped without a commit (an error while
/// producing an output), every temporary is removed and every output is
/// as it was.
///
/// [`stage`]: Outputs::stage
/// [`commit`]: Outputs::commit
///
/// ```
/// use fmaps_mesh_io::atomic::Outputs;
/// let dir = std::env::temp_dir().join(format!("fmaps-outputs-doc-{}", std::process::id()));
/// std::fs::create_dir_all(&dir)?;
/// let (a, b) = (dir.join("a.txt"), dir.join("b.txt"));
/// std::fs::write(&a, "old")?;
/// // The second output fails: the first keeps its old content.
/// let mut out = Outputs::default();
/// out.stage(&a, |tmp| std::fs::write(tmp, "new"))?;
/// assert!(out.stage(&b, |_| Err(std::io::Error::other("no content"))).is_err());
/// drop(out);
/// assert_eq!(std::fs::read_to_string(&a)?, "old");
/// let mut out = Outputs::default();
/// out.stage(&a, |tmp| std::fs::write(tmp, "new"))?;
/// out.stage(&b, |tmp| std::fs::write(tmp, "b"))?;
/// out.commit()?;
/// assert_eq!(std::fs::read_to_string(&a)?, "new");
/// # std::fs::remove_dir_all(&dir)?;
/// # Ok::<(), std::io::Error>(())
/// ```
#[derive(Debug, Default)]
pub struct Outputs {
    staged: Vec<Staged>,
}

impl Outputs {
    /// Produces the content of the output `path` through `write`, given
    /// the temporary path to write it to.
    ///
    /// Errors: `write`'s, and a `path` that cannot be an output (a
    /// directory, a loop of links), as `E` from an [`io::Error`].
    pub fn stage<E: From<io::Error>>(
        &mut self,
        path: &Path,
        write: impl FnOnce(&Path) -> Result<(), E>,
    ) -> Result<(), E> {
        let target = output_target(path)
            .map_err(|e| E::from(io::Error::new(e.kind(), format!("{}: {e}", path.display()))))?;
        let tmp = match &target {
            OutputTarget::File(p) => temporary_path(p),
            OutputTarget::WriteThrough(_) | OutputTarget::Stdout => spool_path(),
        };
        // Registered first, so that a partial temporary is removed too.
        self.staged.push(Staged {
            tmp: tmp.clone(),
            target,
            named: path.to_path_buf(),
        });
        write(&tmp)
    }

    /// Writes every staged output to its target: first the written-through
    /// ones (a device that refuses the bytes fails before any file is
    /// replaced), then the renames.
    ///
    /// Errors: the first failed write or rename, naming the output.
    pub fn commit(mut self) -> io::Result<()> {
        let staged = std::mem::take(&mut self.staged);
        let name = |s: &Staged, e: io::Error| {
            io::Error::new(e.kind(), format!("{}: {e}", s.named.display()))
        };
        let result = (|| {
            for s in &staged {
                match &s.target {
                    OutputTarget::WriteThrough(p) => {
                        copy_into(&s.tmp, open_through(p).map_err(|e| name(s, e))?)
                            .map_err(|e| name(s, e))?;
                    }
                    OutputTarget::Stdout => {
                        copy_into(&s.tmp, io::stdout().lock()).map_err(|e| name(s, e))?;
                    }
                    OutputTarget::File(_) => {}
                }
            }
            for s in &staged {
                if let OutputTarget::File(p) = &s.target {
                    fs::rename(&s.tmp, p).map_err(|e| name(s, e))?;
                }
            }
            Ok(())
        })();
        for s in &staged {
            let _ = fs::remove_file(&s.tmp);
        }
        result
    }
}

/// Copies the file `from` into `to`, flushed.
fn copy_into(from: &Path, to: impl Write) -> io::Result<()> {
    let mut r = fs::File::open(from)?;
    let mut w = BufWriter::new(to);
    let mut buf = vec![0u8; 1 << 16];
    loop {
        let n = r.read(&mut buf)?;
        if n == 0 {
            break;
        }
        w.write_all(&buf[..n])?;
    }
    w.flush()
}

impl Drop for Outputs {
    fn drop(&mut self) {
        for s in &self.staged {
            let _ = fs::remove_file(&s.tmp);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scratch(tag: &str) -> PathBuf {
        let dir = std::env::temp_dir().join(format!("fmaps-atomic-{tag}-{}", std::process::id()));
        let _ = fs::remove_dir_all(&dir);
        fs::create_dir_all(&dir).unwrap();
        dir
    }

    #[test]
    fn a_failed_write_leaves_the_old_file_and_no_temporary() {
        let dir = scratch("fail");
        let p = dir.join("keep.txt");
        fs::write(&p, "old").unwrap();
        let err = write_atomically(&p, |w: &mut dyn Write| {
            w.write_all(b"half")?;
            Err(io::Error::other("disk full"))
        });
        assert!(err.is_err());
        assert_eq!(fs::read_to_string(&p).unwrap(), "old");
        assert_eq!(
            fs::read_dir(&dir).unwrap().count(),
            1,
            "a temporary was left"
        );
        write_atomically(&p, |w: &mut dyn Write| w.write_all(b"new")).unwrap();
        assert_eq!(fs::read_to_string(&p).unwrap(), "new");
        assert_eq!(fs::read_dir(&dir).unwrap().count(), 1);
        // An unwritable target folder: an error, nothing created.
        assert!(write_atomically(&dir.join("no/such/dir/x"), |_: &mut dyn Write| Ok(())).is_err());
        // A directory named as the output: an error, the directory stays.
        assert!(write_atomically(&dir, |_: &mut dyn Write| Ok(())).is_err());
        assert!(dir.is_dir());
        fs::remove_dir_all(&dir).unwrap();
    }

    /// A link to a file: the file gets the content, the link stays a link
    /// (also through a chain of links and a dangling link).
    #[cfg(unix)]
    #[test]
    fn links_are_followed_never_replaced() {
        let dir = scratch("links");
        let file = dir.join("real.txt");
        fs::write(&file, "old").unwrap();
        let link = dir.join("link.txt");
        let chain = dir.join("chain.txt");
        std::os::unix::fs::symlink("real.txt", &link).unwrap();
        std::os::unix::fs::symlink(&link, &chain).unwrap();
        write_atomically(&chain, |w: &mut dyn Write| w.write_all(b"new")).unwrap();
        assert_eq!(fs::read_to_string(&file).unwrap(), "new");
        for l in [&link, &chain] {
            assert!(fs::symlink_metadata(l).unwrap().file_type().is_symlink());
        }
        let dangling = dir.join("dangling.txt");
        std::os::unix::fs::symlink("made.txt", &dangling).unwrap();
        let mut out = Outputs::default();
        out.stage(&dangling, |tmp| fs::write(tmp, "made")).unwrap();
        out.commit().unwrap();
        assert!(
            fs::symlink_metadata(&dangling)
                .unwrap()
                .file_type()
                .is_symlink()
        );
        assert_eq!(fs::read_to_string(dir.join("made.txt")).unwrap(), "made");
        // A loop of links is an error, not a hang.
        std::os::unix::fs::symlink("loop2", dir.join("loop1")).unwrap();
        std::os::unix::fs::symlink("loop1", dir.join("loop2")).unwrap();
        assert!(output_target(&dir.join("loop1")).is_err());
        fs::remove_dir_all(&dir).unwrap();
    }

    /// `Outputs`: a failure while producing any output leaves every output
    /// as it was and no temporary; a commit writes them all.
    #[test]
    fn outputs_are_committed_together_or_not_at_all() {
        let dir = scratch("together");
        let (a, b) = (dir.join("a"), dir.join("b"));
        fs::write(&a, "old a").unwrap();
        fs::write(&b, "old b").unwrap();
        {
            let mut out = Outputs::default();
            out.stage(&a, |tmp| fs::write(tmp, "new a")).unwrap();
            let e = out.stage(&b, |tmp| {
                fs::write(tmp, "half")?;
                Err(io::Error::other("failed"))
            });
            assert!(e.is_err());
        }
        assert_eq!(fs::read_to_string(&a).unwrap(), "old a");
        assert_eq!(fs::read_to_string(&b).unwrap(), "old b");
        assert_eq!(fs::read_dir(&dir).unwrap().count(), 2);
        // A directory as the second output: refused when staged.
        let mut out = Outputs::default();
        out.stage(&a, |tmp| fs::write(tmp, "new a")).unwrap();
        assert!(out.stage(&dir, |tmp| fs::write(tmp, "x")).is_err());
        drop(out);
        assert_eq!(fs::read_to_string(&a).unwrap(), "old a");
        let mut out = Outputs::default();
        out.stage(&a, |tmp| fs::write(tmp, "new a")).unwrap();
        out.stage(&b, |tmp| fs::write(tmp, "new b")).unwrap();
        out.commit().unwrap();
        assert_eq!(fs::read_to_string(&a).unwrap(), "new a");
        assert_eq!(fs::read_to_string(&b).unwrap(), "new b");
        assert_eq!(fs::read_dir(&dir).unwrap().count(), 2);
        fs::remove_dir_all(&dir).unwrap();
    }
}
