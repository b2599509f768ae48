//! The session directory kept up to date while a session runs, so nothing measured is lost when
//! the session stops early (a board that vanishes, a lost reply, Ctrl-C, a timeout):
//! `poses.json` after every captured pose, `mag_samples.csv` and `moves.csv` after every phase
//! and when the session stops (rewriting the moves at every pose would slow the session as
//! they grow), `params.json`
//! once fitted, and `progress.json` saying how far the session got and what the board holds.
//! `save_session` writes the finished directory and removes `progress.json`.

use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use super::save::{
    create_dir, mag_csv, moves_csv, poses_json, write_file, MOVES_FILE, PROGRESS_FILE,
};
use super::{CapturedPose, MagSample, SessionError};
use crate::device::{ParamsFile, UnitSample};
use imucal_protocol::CalibrationSet;

/// How far an unfinished session got (`progress.json`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Progress {
    /// The board's id (a session continues only on the board it started on).
    pub device_id: String,
    /// The last stage reached: `positions`, `magnetometer`, `rest`, `fitted`, `writing`,
    /// `after` (the check at rest with the written set) or `stopped`.
    pub stage: String,
    /// Why the session stopped (empty while it runs).
    pub stopped_because: String,
    /// What the board holds, in words.
    pub board_holds: String,
    /// Poses saved in `poses.json`.
    pub poses: usize,
    /// Samples saved in `mag_samples.csv`.
    pub mag_samples: usize,
    /// CRC-32 of the fitted set in `params.json`, once fitted.
    pub params_crc: Option<String>,
}

/// Writes the session directory as the session goes; does nothing without a directory.
#[derive(Debug)]
pub(super) struct Journal {
    dir: Option<PathBuf>,
    poses: Vec<CapturedPose>,
    progress: Progress,
}

impl Journal {
    /// A journal writing into `dir` (created now, so an unwritable directory stops the session
    /// before anything is measured).
    pub(super) fn new(dir: Option<&Path>, device_id: String) -> Result<Self, SessionError> {
        if let Some(dir) = dir {
            create_dir(dir)?;
        }
        Ok(Self {
            dir: dir.map(Path::to_path_buf),
            poses: Vec::new(),
            progress: Progress {
                device_id,
                stage: "positions".to_string(),
                stopped_because: String::new(),
                board_holds: "its earlier set (nothing written yet)".to_string(),
                poses: 0,
                mag_samples: 0,
                params_crc: None,
            },
        })
    }

    fn write(&self, name: &str, text: impl FnOnce() -> String) -> Result<(), SessionError> {
        match &self.dir {
            Some(dir) => write_file(&dir.join(name), &text()).map(|_| ()),
            None => Ok(()),
        }
    }

    fn write_progress(&self) -> Result<(), SessionError> {
        self.write(PROGRESS_FILE, || {
            serde_json::to_string_pretty(&self.progress).unwrap_or_default()
        })
    }

    /// Poses, magnetometer samples and moves measured before this run (a resumed session):
    /// saved again with the new ones. The moves are written now, so a directory reused by a
    /// new session holds no moves of an older one.
    pub(super) fn resume_with(
        &mut self,
        poses: &[CapturedPose],
        mag: &[MagSample],
        moves: &[Vec<UnitSample>],
    ) -> Result<(), SessionError> {
        self.poses = poses.to_vec();
        self.progress.poses = self.poses.len();
        self.progress.mag_samples = mag.len();
        self.write(MOVES_FILE, || moves_csv(moves))
    }

    /// A pose was captured.
    pub(super) fn pose(&mut self, pose: &CapturedPose) -> Result<(), SessionError> {
        self.poses.push(pose.clone());
        self.progress.poses = self.poses.len();
        self.write("poses.json", || poses_json(&self.poses))?;
        self.write_progress()
    }

    /// A phase ended with `mag` streamed and `moves` kept so far; `stage` is the one starting.
    pub(super) fn stage(
        &mut self,
        stage: &str,
        mag: &[MagSample],
        moves: &[Vec<UnitSample>],
    ) -> Result<(), SessionError> {
        self.progress.stage = stage.to_string();
        self.progress.mag_samples = mag.len();
        self.write("mag_samples.csv", || mag_csv(mag))?;
        self.write(MOVES_FILE, || moves_csv(moves))?;
        self.write_progress()
    }

    /// The set was fitted (and is about to be offered for writing).
    pub(super) fn fitted(&mut self, set: &CalibrationSet) -> Result<(), SessionError> {
        self.progress.stage = "fitted".to_string();
        self.progress.params_crc = Some(format!("{:#010x}", set.crc32()));
        self.write("params.json", || ParamsFile::from(set).to_json())?;
        self.write_progress()
    }

    /// The session stopped: say why and what the board holds. Errors writing are ignored here
    /// (the session's own error is the one to report), but reported in the returned note.
    pub(super) fn stopped(
        &mut self,
        because: &str,
        board_holds: &str,
        mag: &[MagSample],
        moves: &[Vec<UnitSample>],
    ) -> String {
        self.progress.stopped_because = because.to_string();
        self.progress.board_holds = board_holds.to_string();
        let Some(dir) = self.dir.clone() else {
            return "nothing was saved (no session directory was given)".to_string();
        };
        let stage = std::mem::replace(&mut self.progress.stage, "stopped".to_string());
        self.progress.stopped_because = format!("{because} (during stage `{stage}`)");
        match self.stage("stopped", mag, moves) {
            Ok(()) => format!(
                "what was measured ({} positions, {} magnetometer samples) is saved in {}",
                self.progress.poses,
                self.progress.mag_samples,
                dir.display()
            ),
            Err(error) => format!("saving what was measured failed: {error}"),
        }
    }
}

/// Read the `progress.json` of an unfinished session directory.
pub fn load_progress(dir: &Path) -> Result<Progress, SessionError> {
    let path = dir.join(PROGRESS_FILE);
    let load_error = |reason: String| SessionError::Load {
        path: path.display().to_string(),
        reason,
    };
    let text = std::fs::read_to_string(&path).map_err(|e| load_error(e.to_string()))?;
    serde_json::from_str(&text).map_err(|e| load_error(e.to_string()))
}
