//! Files that leave the program (docs/design.md §4): `.npz` containers, demonstrations (also
//! as LeRobot datasets and CSV), gain tables, the MDGPS policy, MCAP logs of recorded runs.

pub mod checkpoint;
pub mod demos;
pub mod episode;
pub mod files;
pub mod foreign;
pub mod learned;
pub mod lerobot;
pub mod log;
pub mod manifest;
pub mod npz;
pub mod policy;
pub mod run_mcap;
pub mod table;

/// Creates the folder `dir` and its parents (an `--out` folder or one inside it); the error
/// names the folder, whatever the OS says.
pub fn create_dir(dir: impl AsRef<std::path::Path>) -> anyhow::Result<()> {
    let dir = dir.as_ref();
    std::fs::create_dir_all(dir)
        .map_err(|e| anyhow::anyhow!("cannot create the folder {}: {e}", dir.display()))
}
