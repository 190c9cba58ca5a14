//! Where a run keeps its files: a run directory on disk, or memory for the in-memory API.
//!
//! The pipeline reads and writes its working files (tile stores, per-tile results, the
//! manifest) only through a [`Workspace`], by names relative to it, so the same code runs over
//! a resumable run directory and over a cloud held in memory.

use crate::error::{io_input, Error, Result};
use std::collections::HashMap;
use std::io::{BufReader, Read};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

/// A run directory on disk, or its stand-in in memory.
pub(crate) struct Workspace {
    root: PathBuf,
    /// The files, when in memory.
    memory: Option<Mutex<HashMap<String, Arc<Vec<u8>>>>>,
    /// The run directory's lock file, locked, once [`Workspace::lock`] took it.
    lock: Option<std::fs::File>,
    /// A worker's own lock file (`lock.<i>`), locked, once [`Workspace::lock`] took it, and its
    /// name.
    worker_lock: Option<(std::fs::File, String)>,
    /// True if [`Workspace::disk`] made the run directory: it is removed again if nothing but
    /// the lock was ever written to it (a run refused at its start).
    created: bool,
    /// Where the working files live when not in the run directory (see
    /// [`Workspace::set_work_dir`]): that directory, and the top-level names that go there.
    work: Option<(PathBuf, &'static [&'static str])>,
}

/// The lock file of a run directory.
pub(crate) const LOCK: &str = "lock";

impl Drop for Workspace {
    fn drop(&mut self) {
        self.release();
    }
}

/// True if `f` is the file at `path` (not one removed from it since it was opened).
fn same_file(f: &std::fs::File, path: &Path) -> bool {
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        match (f.metadata(), std::fs::metadata(path)) {
            (Ok(a), Ok(b)) => a.dev() == b.dev() && a.ino() == b.ino(),
            _ => false,
        }
    }
    #[cfg(not(unix))]
    {
        let _ = (f, path);
        true
    }
}

impl Workspace {
    /// The run directory `dir` (created if needed).
    pub(crate) fn disk(dir: &Path) -> Result<Workspace> {
        let created = !dir.exists();
        std::fs::create_dir_all(dir).map_err(|e| Error::output(dir, e))?;
        Ok(Workspace { root: dir.to_path_buf(), memory: None, lock: None, worker_lock: None, work: None, created })
    }

    /// A workspace that keeps its files in memory.
    pub(crate) fn memory() -> Workspace {
        Workspace { root: PathBuf::from("<memory>"), memory: Some(Mutex::new(HashMap::new())), lock: None, worker_lock: None, work: None, created: false }
    }

    /// Takes the run directory for this process until the workspace is dropped: an advisory
    /// lock on its lock file, which then holds this process's id. A directory another process
    /// holds is refused, naming that process.
    ///
    /// Worker `i` of a run shared by several (`Some(i)`) shares the lock file with the other
    /// workers and takes `lock.<i>` alone: workers run side by side, each index once, and a
    /// lone run neither joins them nor lets them in.
    pub(crate) fn lock(&mut self, worker: Option<u32>) -> Result<()> {
        if self.memory.is_some() || self.lock.is_some() {
            return Ok(());
        }
        use std::io::{Seek, Write};
        let open = |name: &str| {
            let p = self.path(name);
            std::fs::OpenOptions::new().read(true).write(true).create(true).truncate(false).open(&p).map_err(|e| Error::output(&p, e))
        };
        let refused = |f: &mut std::fs::File, what: &str| {
            let mut holder = String::new();
            let _ = f.read_to_string(&mut holder);
            // (The file names the last lone run or worker to take it; if that process is gone,
            // the holders are workers, which do not write it.)
            let pid = holder.trim().parse::<u32>().ok().filter(|pid| Path::new(&format!("/proc/{pid}")).exists() || !Path::new("/proc/self").exists());
            let who = pid.map_or("crease workers".to_string(), |pid| format!("process {pid}"));
            Error::Usage(format!("{}: in use by {what} ({who}); wait for it to end, or stop it, before running here", self.root.display()))
        };
        // (The lock file is removed when a run ends, by the process that holds it alone; one
        // taken by another process in between is the removed file, not the one at the path:
        // then it is opened again.)
        let f = loop {
            let mut f = open(LOCK)?;
            let taken = match worker {
                None => f.try_lock(),
                Some(_) => f.try_lock_shared(),
            };
            match taken {
                Ok(()) => {}
                Err(std::fs::TryLockError::WouldBlock) => return Err(refused(&mut f, "another crease run")),
                Err(std::fs::TryLockError::Error(e)) => return Err(Error::output(self.path(LOCK), e)),
            }
            if same_file(&f, &self.path(LOCK)) {
                break f;
            }
        };
        let mut own = match worker {
            None => f.try_clone().map_err(|e| Error::output(self.path(LOCK), e))?,
            Some(i) => {
                let name = format!("{LOCK}.{i}");
                let w = loop {
                    let mut w = open(&name)?;
                    match w.try_lock() {
                        Ok(()) => {}
                        Err(std::fs::TryLockError::WouldBlock) => return Err(refused(&mut w, &format!("worker {i}"))),
                        Err(std::fs::TryLockError::Error(e)) => return Err(Error::output(self.path(&name), e)),
                    }
                    if same_file(&w, &self.path(&name)) {
                        break w;
                    }
                };
                self.worker_lock = Some((w.try_clone().map_err(|e| Error::output(self.path(&name), e))?, name));
                w
            }
        };
        let r = own.set_len(0).and_then(|_| own.rewind()).and_then(|_| writeln!(own, "{}", std::process::id()));
        r.map_err(|e| Error::output(self.path(LOCK), e))?;
        self.lock = Some(f);
        Ok(())
    }

    /// Lets the run directory go: the lock files are removed (the run's own, `lock`, only by
    /// the last process holding it), and the directory itself if this workspace made it and
    /// nothing else was written to it.
    fn release(&mut self) {
        if let Some((w, name)) = self.worker_lock.take() {
            let _ = std::fs::remove_file(self.path(&name));
            drop(w);
        }
        if let Some(f) = self.lock.take() {
            // (A worker holds the lock shared: it is the last one if it can take it alone.)
            if f.try_lock().is_ok() {
                let _ = std::fs::remove_file(self.path(LOCK));
            }
            drop(f);
            if self.created {
                let _ = std::fs::remove_dir(&self.root);
            }
        }
    }

    /// The root directory.
    pub(crate) fn root(&self) -> &Path {
        &self.root
    }

    /// Puts the files and directories named `names` (top-level names, such as `tiles`) in
    /// `dir` instead of the run directory from now on (created if needed), or back in the run
    /// directory for None. In memory, nothing changes.
    pub(crate) fn set_work_dir(&mut self, dir: Option<&Path>, names: &'static [&'static str]) -> Result<()> {
        if self.memory.is_some() {
            return Ok(());
        }
        if let Some(dir) = dir {
            std::fs::create_dir_all(dir).map_err(|e| Error::output(dir, e))?;
        }
        self.work = dir.map(|d| (d.to_path_buf(), names));
        Ok(())
    }

    /// The path of `name` (for messages, and for files only disk runs write).
    pub(crate) fn path(&self, name: &str) -> PathBuf {
        match &self.work {
            Some((dir, names)) if names.contains(&name.split('/').next().unwrap_or(name)) => dir.join(name),
            _ => self.root.join(name),
        }
    }

    fn files(&self) -> Option<std::sync::MutexGuard<'_, HashMap<String, Arc<Vec<u8>>>>> {
        self.memory.as_ref().map(|m| m.lock().unwrap_or_else(|e| e.into_inner()))
    }

    /// Creates the directory `name`.
    pub(crate) fn create_dir(&self, name: &str) -> Result<()> {
        if self.memory.is_some() {
            return Ok(());
        }
        let p = self.path(name);
        std::fs::create_dir_all(&p).map_err(|e| Error::output(&p, e))
    }

    /// Removes the file or directory `name`, if there is one.
    pub(crate) fn remove(&self, name: &str) {
        if let Some(mut files) = self.files() {
            let dir = format!("{name}/");
            files.retain(|k, _| k != name && !k.starts_with(&dir));
            return;
        }
        let p = self.path(name);
        let _ = if p.is_dir() { std::fs::remove_dir_all(&p) } else { std::fs::remove_file(&p) };
    }

    /// True if the file `name` exists.
    pub(crate) fn exists(&self, name: &str) -> bool {
        match self.files() {
            Some(files) => files.contains_key(name),
            None => self.path(name).exists(),
        }
    }

    /// The bytes of file `name`, or None if there is no such file.
    pub(crate) fn read(&self, name: &str) -> Result<Option<Vec<u8>>> {
        if let Some(files) = self.files() {
            return Ok(files.get(name).map(|b| b.to_vec()));
        }
        let p = self.path(name);
        match std::fs::read(&p) {
            Ok(b) => Ok(Some(b)),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(io_input(&p, e)),
        }
    }

    /// Writes file `name` atomically: temporary file, fsync, rename, fsync of the directory.
    pub(crate) fn write_atomic(&self, name: &str, bytes: &[u8]) -> Result<()> {
        match self.files() {
            Some(mut files) => {
                files.insert(name.to_string(), Arc::new(bytes.to_vec()));
                Ok(())
            }
            None => write_atomic(&self.path(name), bytes),
        }
    }

    /// Appends `bytes` to file `name` (created if need be).
    pub(crate) fn append(&self, name: &str, bytes: &[u8]) -> Result<()> {
        if let Some(mut files) = self.files() {
            Arc::make_mut(files.entry(name.to_string()).or_default()).extend_from_slice(bytes);
            return Ok(());
        }
        use std::io::Write;
        let p = self.path(name);
        let r = std::fs::OpenOptions::new().create(true).append(true).open(&p).and_then(|mut f| f.write_all(bytes));
        r.map_err(|e| Error::output(&p, e))
    }

    /// Makes every file of directory `name` durable.
    pub(crate) fn sync_dir(&self, name: &str) -> Result<()> {
        if self.memory.is_some() {
            return Ok(());
        }
        let dir = self.path(name);
        for e in std::fs::read_dir(&dir).map_err(|e| Error::output(&dir, e))?.flatten() {
            std::fs::File::open(e.path()).and_then(|f| f.sync_all()).map_err(|err| Error::output(e.path(), err))?;
        }
        Ok(())
    }

    /// A stream over file `name`, or None if there is no such file.
    pub(crate) fn open(&self, name: &str) -> Result<Option<Source>> {
        if let Some(files) = self.files() {
            return Ok(files.get(name).map(|b| Source::Memory(b.clone(), 0)));
        }
        let p = self.path(name);
        match std::fs::File::open(&p) {
            Ok(f) => Ok(Some(Source::File(BufReader::new(f)))),
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => Ok(None),
            Err(e) => Err(io_input(&p, e)),
        }
    }
}

/// A file being read front to back, with skips.
pub(crate) enum Source {
    /// A file on disk.
    File(BufReader<std::fs::File>),
    /// A file in memory and the read position.
    Memory(Arc<Vec<u8>>, usize),
}

impl Source {
    /// Fills `buf`; false at the end of the file (nothing read).
    pub(crate) fn read_exact_or_end(&mut self, buf: &mut [u8]) -> std::io::Result<bool> {
        match self {
            Source::File(f) => {
                // (The end of the file only before the first byte: a part of `buf` is a
                // truncated file.)
                let mut got = 0;
                while got < buf.len() {
                    match f.read(&mut buf[got..]) {
                        Ok(0) if got == 0 => return Ok(false),
                        Ok(0) => return Err(std::io::ErrorKind::UnexpectedEof.into()),
                        Ok(n) => got += n,
                        Err(e) if e.kind() == std::io::ErrorKind::Interrupted => {}
                        Err(e) => return Err(e),
                    }
                }
                Ok(true)
            }
            Source::Memory(b, at) => {
                if *at >= b.len() {
                    return Ok(false);
                }
                let end = at.checked_add(buf.len()).filter(|&e| e <= b.len()).ok_or(std::io::ErrorKind::UnexpectedEof)?;
                buf.copy_from_slice(&b[*at..end]);
                *at = end;
                Ok(true)
            }
        }
    }

    /// Fills `buf`, which must be there.
    pub(crate) fn read_exact(&mut self, buf: &mut [u8]) -> std::io::Result<()> {
        if self.read_exact_or_end(buf)? || buf.is_empty() {
            Ok(())
        } else {
            Err(std::io::ErrorKind::UnexpectedEof.into())
        }
    }

    /// Skips `n` bytes.
    pub(crate) fn skip(&mut self, n: usize) -> std::io::Result<()> {
        match self {
            Source::File(f) => f.seek_relative(n as i64),
            Source::Memory(b, at) => {
                *at = at.saturating_add(n).min(b.len() + 1);
                Ok(())
            }
        }
    }
}

/// Writes `bytes` to `path` atomically: temporary file, fsync, rename, fsync of the directory.
pub(crate) fn write_atomic(path: &Path, bytes: &[u8]) -> Result<()> {
    use std::io::Write;
    let tmp = path.with_extension("tmp");
    let r = (|| {
        let mut f = std::fs::File::create(&tmp)?;
        f.write_all(bytes)?;
        f.sync_all()?;
        std::fs::rename(&tmp, path)?;
        if let Some(dir) = path.parent() {
            std::fs::File::open(dir)?.sync_all()?;
        }
        Ok(())
    })();
    r.map_err(|e| {
        // (A full disk must not leave the partial temporary file behind.)
        let _ = std::fs::remove_file(&tmp);
        Error::output(path, e)
    })
}
