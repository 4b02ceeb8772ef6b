//! Atomic file replacement for every file a run writes that a restart reads back (checkpoints,
//! critic files, the run manifest, rewritten CSVs; docs/design.md §4.1): the bytes go to a
//! temporary file in the same folder, which is flushed to disk (`fsync`) and renamed over the
//! final name, and the folder is synced so that the rename itself is durable. A process killed
//! at any moment leaves either the old file or the new one under the final name, never a
//! truncated mix; at worst a stale temporary file (`<name>.tmp`) that readers ignore.

use std::fs::File;
use std::io::Write;
use std::path::{Path, PathBuf};

/// The temporary name `path` is written under before the rename: `<path>.tmp`.
pub fn temporary_path(path: &Path) -> PathBuf {
    let mut tmp = path.as_os_str().to_owned();
    tmp.push(".tmp");
    PathBuf::from(tmp)
}

/// Writes `bytes` to `path` atomically (module docs). The error names the file at fault.
pub fn write(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    let tmp = write_temporary(path, bytes)?;
    commit(&tmp, path)
}

/// The error `e` naming the file `p`.
fn named(e: std::io::Error, p: &Path) -> std::io::Error {
    std::io::Error::new(e.kind(), format!("{}: {e}", p.display()))
}

/// Writes `bytes` to `path`'s temporary file and syncs it; returns the temporary's path.
fn write_temporary(path: &Path, bytes: &[u8]) -> std::io::Result<PathBuf> {
    let tmp = temporary_path(path);
    let mut f = File::create(&tmp).map_err(|e| named(e, &tmp))?;
    f.write_all(bytes).map_err(|e| named(e, &tmp))?;
    f.sync_all().map_err(|e| named(e, &tmp))?;
    Ok(tmp)
}

/// Writes `bytes` to `path` atomically as a new file: never replaces what is there (a file,
/// a FIFO, a device; error kind `AlreadyExists`, also when another process creates `path`
/// meanwhile), since the complete temporary file is hard-linked to the final name, which fails
/// when the name exists. The error names the file at fault.
pub fn write_new(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    if std::fs::symlink_metadata(path).is_ok() {
        return Err(std::io::Error::new(
            std::io::ErrorKind::AlreadyExists,
            format!("{} exists", path.display()),
        ));
    }
    let tmp = write_temporary(path, bytes)?;
    let linked = std::fs::hard_link(&tmp, path).map_err(|e| named(e, path));
    std::fs::remove_file(&tmp).ok();
    linked?;
    sync_parent(path)
}

/// Renames the complete, synced file `tmp` to `path` and syncs their folder.
pub fn commit(tmp: &Path, path: &Path) -> std::io::Result<()> {
    std::fs::rename(tmp, path).map_err(|e| {
        std::io::Error::new(
            e.kind(),
            format!("renaming {} to {}: {e}", tmp.display(), path.display()),
        )
    })?;
    sync_parent(path)
}

/// `fsync` of the folder holding `path` (makes a rename durable; a no-op where folders cannot
/// be opened).
pub fn sync_parent(path: &Path) -> std::io::Result<()> {
    let dir = match path.parent() {
        Some(d) if !d.as_os_str().is_empty() => d,
        _ => Path::new("."),
    };
    match File::open(dir) {
        Ok(d) => d.sync_all().or(Ok(())),
        Err(_) => Ok(()),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn replaces_the_file_and_leaves_no_temporary() {
        let dir = std::env::temp_dir().join(format!("atomic-file-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.json");
        write(&p, b"one").unwrap();
        write(&p, b"two").unwrap();
        assert_eq!(std::fs::read(&p).unwrap(), b"two");
        assert!(!temporary_path(&p).exists());
        let e = write(&dir.join("missing/b.json"), b"x").unwrap_err();
        assert!(e.to_string().contains("missing/b.json.tmp"), "{e}");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_new_file_never_replaces_one() {
        let dir = std::env::temp_dir().join(format!("atomic-new-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let p = dir.join("a.csv");
        write_new(&p, b"one").unwrap();
        let e = write_new(&p, b"two").unwrap_err();
        assert_eq!(e.kind(), std::io::ErrorKind::AlreadyExists, "{e}");
        assert_eq!(std::fs::read(&p).unwrap(), b"one");
        assert!(!temporary_path(&p).exists());
        std::fs::remove_dir_all(&dir).unwrap();
    }
}
