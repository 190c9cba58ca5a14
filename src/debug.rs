//! Intermediate point sets written for inspection (`--debug-dir`): candidates per tile, the
//! edge cloud, the smoothed edge cloud, corners, grown polylines, as OBJ files.

use glam::DVec3;
use std::path::PathBuf;

/// Where intermediate point sets go, if anywhere.
#[derive(Clone, Debug, Default)]
pub struct DebugDump {
    dir: Option<PathBuf>,
}

impl DebugDump {
    /// Dumps to `dir`, or nowhere for None.
    pub fn new(dir: Option<PathBuf>) -> DebugDump {
        DebugDump { dir }
    }

    /// True if dumps are written.
    pub fn on(&self) -> bool {
        self.dir.is_some()
    }

    /// Writes `pts` (relative to `origin`) as OBJ vertices to `name`; failures are ignored (a
    /// debugging aid must not stop a run).
    pub fn points(&self, name: &str, pts: &[DVec3], origin: DVec3) {
        let Some(dir) = &self.dir else { return };
        let text: String = pts
            .iter()
            .map(|p| {
                let p = *p + origin;
                format!("v {} {} {}\n", p.x, p.y, p.z)
            })
            .collect();
        let _ = std::fs::create_dir_all(dir).and_then(|_| std::fs::write(dir.join(name), text));
    }

    /// Writes polylines (world coordinates) to `name` as OBJ.
    pub fn polylines(&self, name: &str, curves: &[crate::curves::Polyline]) {
        if let Some(dir) = &self.dir {
            let _ = std::fs::create_dir_all(dir).is_ok().then(|| crate::curves::write_obj(&dir.join(name), curves, &Default::default()));
        }
    }
}
