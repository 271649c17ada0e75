//! Where a fleet binary finds its data: the simulator's scenarios, the ONNX models and the
//! `shared/` reference data (the Nav2 maps). No source-tree path is compiled into a binary, so an
//! installed binary works anywhere; every binary looks its folders up here, the same way.
//!
//! Each [`DataKind`] is looked up in this order, the first hit wins:
//!
//! 1. an explicit path (a command-line flag), which must be a directory;
//! 2. its environment variable ([`DataKind::env_var`]: `FLEET_SHARED_DIR`,
//!    `FLEET_SCENARIOS_DIR`, `FLEET_MODELS_DIR`) when set and non-empty, which must be a
//!    directory;
//! 3. folders relative to the current directory ([`DataKind::relative_candidates`]: scripts run
//!    from the repository root): `shared`, `../shared`; `sim/scenarios`, `scenarios`; `models`;
//! 4. the user's data directory ([`user_data_dir`], `~/.local/share/intention-fleet` on Linux):
//!    `<data>/shared`, `<data>/scenarios`, `<data>/models`.
//!
//! A wrong explicit path or environment value is an error, not a silent fall-back to another
//! folder; when nothing is found the error lists every place that was tried. [`find_in`] takes
//! every input as plain data ([`Places`]), so it is tested without touching the process's
//! environment or the user's home; [`find_dir`] and the `find_*` helpers read them from the
//! process.

use std::ffi::OsStr;
use std::fmt;
use std::path::{Path, PathBuf};

/// A folder of data that binaries look up at run time.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum DataKind {
    /// `shared/`: the reference data beside the repository (`maps/nav2/*.yaml`).
    Shared,
    /// The simulator's scenarios (`task_a.yaml`, …, floor plans in `maps/`).
    Scenarios,
    /// ONNX models of the network controllers (`dlm.onnx`, `lpe.onnx`, `none.onnx`).
    Models,
}

impl DataKind {
    /// Every kind.
    pub const ALL: [DataKind; 3] = [Self::Shared, Self::Scenarios, Self::Models];

    /// The environment variable naming the folder.
    #[must_use]
    pub fn env_var(self) -> &'static str {
        match self {
            Self::Shared => "FLEET_SHARED_DIR",
            Self::Scenarios => "FLEET_SCENARIOS_DIR",
            Self::Models => "FLEET_MODELS_DIR",
        }
    }

    /// Folders tried relative to the current directory, in order.
    #[must_use]
    pub fn relative_candidates(self) -> &'static [&'static str] {
        match self {
            Self::Shared => &["shared", "../shared"],
            Self::Scenarios => &["sim/scenarios", "scenarios"],
            Self::Models => &["models"],
        }
    }

    /// The folder's name inside the user's data directory.
    #[must_use]
    pub fn user_subdir(self) -> &'static str {
        match self {
            Self::Shared => "shared",
            Self::Scenarios => "scenarios",
            Self::Models => "models",
        }
    }
}

impl fmt::Display for DataKind {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Shared => "shared data",
            Self::Scenarios => "scenarios",
            Self::Models => "models",
        })
    }
}

/// Why a data folder was not found.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum DataDirError {
    /// An explicit path or environment value that is not a directory.
    #[error("the {kind} folder {} given by {given_by} is not a directory", path.display())]
    NotADirectory {
        kind: DataKind,
        path: PathBuf,
        /// `a command-line flag` or the environment variable's name.
        given_by: String,
    },
    /// No candidate exists.
    #[error(
        "no {kind} folder found; looked in: {}; pass its command-line flag, set {}, run from the \
         repository root, or put the folder there",
        tried.join(", "),
        kind.env_var()
    )]
    NotFound {
        kind: DataKind,
        /// Every place tried, in order, each with where it came from.
        tried: Vec<String>,
    },
}

/// The inputs of a lookup besides the explicit path and the environment variable.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Places {
    /// The current directory (`None`: unknown, its candidates are skipped).
    pub cwd: Option<PathBuf>,
    /// The user's data directory (`None`: the platform has none).
    pub user_data_dir: Option<PathBuf>,
}

impl Places {
    /// The running process's current directory and user data directory.
    #[must_use]
    pub fn of_process() -> Self {
        Self {
            cwd: std::env::current_dir().ok(),
            user_data_dir: user_data_dir(),
        }
    }
}

/// The user's data directory of the fleet (`directories::ProjectDirs` for
/// `org.intention-fleet`): `$XDG_DATA_HOME/intention-fleet` or
/// `~/.local/share/intention-fleet` on Linux, `~/Library/Application Support/org.intention-fleet.intention-fleet`
/// on macOS. `None` when the platform reports no home directory.
#[must_use]
pub fn user_data_dir() -> Option<PathBuf> {
    directories::ProjectDirs::from("org", "intention-fleet", "intention-fleet")
        .map(|d| d.data_dir().to_path_buf())
}

/// Looks up a `kind` folder from plain inputs: the explicit path, the value of the kind's
/// environment variable (`None` or empty: unset) and the other [`Places`].
///
/// # Errors
/// [`DataDirError::NotADirectory`] for an explicit path or environment value that is not a
/// directory, [`DataDirError::NotFound`] listing every place tried.
pub fn find_in(
    kind: DataKind,
    explicit: Option<&Path>,
    env_value: Option<&OsStr>,
    places: &Places,
) -> Result<PathBuf, DataDirError> {
    if let Some(path) = explicit {
        return existing(kind, path, "a command-line flag");
    }
    if let Some(value) = env_value.filter(|v| !v.is_empty()) {
        return existing(kind, Path::new(value), kind.env_var());
    }
    let mut tried = vec![format!("${} (not set)", kind.env_var())];
    let relative = places.cwd.iter().flat_map(|cwd| {
        kind.relative_candidates()
            .iter()
            .map(move |rel| (cwd.join(rel), "current directory"))
    });
    let user = places
        .user_data_dir
        .iter()
        .map(|data| (data.join(kind.user_subdir()), "user data directory"));
    for (candidate, from) in relative.chain(user) {
        if candidate.is_dir() {
            return Ok(candidate);
        }
        tried.push(format!("{} ({from})", candidate.display()));
    }
    if places.user_data_dir.is_none() {
        tried.push("no user data directory (no home directory)".to_string());
    }
    Err(DataDirError::NotFound { kind, tried })
}

fn existing(kind: DataKind, path: &Path, given_by: &str) -> Result<PathBuf, DataDirError> {
    if path.is_dir() {
        Ok(path.to_path_buf())
    } else {
        Err(DataDirError::NotADirectory {
            kind,
            path: path.to_path_buf(),
            given_by: given_by.to_string(),
        })
    }
}

/// Looks up a `kind` folder for this process: `explicit`, then the environment variable, the
/// current directory and the user's data directory (see the module docs).
///
/// # Errors
/// As [`find_in`].
pub fn find_dir(kind: DataKind, explicit: Option<&Path>) -> Result<PathBuf, DataDirError> {
    let env = std::env::var_os(kind.env_var());
    find_in(kind, explicit, env.as_deref(), &Places::of_process())
}

/// The `shared/` folder ([`DataKind::Shared`]).
///
/// # Errors
/// As [`find_in`].
pub fn find_shared_dir(explicit: Option<&Path>) -> Result<PathBuf, DataDirError> {
    find_dir(DataKind::Shared, explicit)
}

/// The Nav2 reference maps, `maps/nav2` in the `shared/` folder.
///
/// # Errors
/// As [`find_in`] for the shared folder.
pub fn find_nav2_maps_dir(explicit_shared: Option<&Path>) -> Result<PathBuf, DataDirError> {
    Ok(find_shared_dir(explicit_shared)?.join("maps").join("nav2"))
}

/// The simulator's scenarios ([`DataKind::Scenarios`]).
///
/// # Errors
/// As [`find_in`].
pub fn find_scenarios_dir(explicit: Option<&Path>) -> Result<PathBuf, DataDirError> {
    find_dir(DataKind::Scenarios, explicit)
}

/// The ONNX models ([`DataKind::Models`]).
///
/// # Errors
/// As [`find_in`].
pub fn find_models_dir(explicit: Option<&Path>) -> Result<PathBuf, DataDirError> {
    find_dir(DataKind::Models, explicit)
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used)]

    use super::*;

    /// A fake layout: a working directory and a user data directory under one temp folder.
    fn layout() -> (tempfile::TempDir, Places) {
        let root = tempfile::tempdir().unwrap();
        let places = Places {
            cwd: Some(root.path().join("work")),
            user_data_dir: Some(root.path().join("data")),
        };
        std::fs::create_dir_all(root.path().join("work")).unwrap();
        (root, places)
    }

    fn mkdir(path: &Path) -> PathBuf {
        std::fs::create_dir_all(path).unwrap();
        path.to_path_buf()
    }

    #[test]
    fn an_explicit_path_wins_over_everything_else() {
        let (root, places) = layout();
        let flag = mkdir(&root.path().join("flag"));
        let env = mkdir(&root.path().join("env"));
        mkdir(&root.path().join("work/sim/scenarios"));
        mkdir(&root.path().join("data/scenarios"));
        let found = find_in(
            DataKind::Scenarios,
            Some(&flag),
            Some(env.as_os_str()),
            &places,
        )
        .unwrap();
        assert_eq!(found, flag);
    }

    #[test]
    fn the_environment_wins_over_the_current_and_user_directories() {
        let (root, places) = layout();
        let env = mkdir(&root.path().join("env"));
        mkdir(&root.path().join("work/models"));
        mkdir(&root.path().join("data/models"));
        let found = find_in(DataKind::Models, None, Some(env.as_os_str()), &places).unwrap();
        assert_eq!(found, env);
        // An empty value counts as unset.
        let found = find_in(DataKind::Models, None, Some(OsStr::new("")), &places).unwrap();
        assert_eq!(found, root.path().join("work/models"));
    }

    #[test]
    fn a_wrong_explicit_or_environment_path_is_an_error_not_a_fallback() {
        let (root, places) = layout();
        mkdir(&root.path().join("work/models"));
        let missing = root.path().join("nope");
        let err = find_in(DataKind::Models, Some(&missing), None, &places).unwrap_err();
        assert!(
            matches!(&err, DataDirError::NotADirectory { path, .. } if *path == missing),
            "{err}"
        );
        let err = find_in(DataKind::Models, None, Some(missing.as_os_str()), &places).unwrap_err();
        let msg = err.to_string();
        assert!(
            msg.contains("FLEET_MODELS_DIR") && msg.contains(&missing.display().to_string()),
            "{msg}"
        );
    }

    #[test]
    fn the_current_directory_comes_before_the_user_data_directory_in_order() {
        let (root, places) = layout();
        // `../shared` from the working directory: the repository-root layout.
        let beside = mkdir(&root.path().join("shared"));
        mkdir(&root.path().join("data/shared"));
        assert_eq!(
            find_in(DataKind::Shared, None, None, &places).unwrap(),
            places.cwd.as_ref().unwrap().join("../shared")
        );
        std::fs::remove_dir(&beside).unwrap();
        assert_eq!(
            find_in(DataKind::Shared, None, None, &places).unwrap(),
            root.path().join("data/shared")
        );
        // The first relative candidate wins over the second.
        let scen = mkdir(&root.path().join("work/sim/scenarios"));
        mkdir(&root.path().join("work/scenarios"));
        assert_eq!(
            find_in(DataKind::Scenarios, None, None, &places).unwrap(),
            scen
        );
    }

    #[test]
    fn not_found_lists_every_place_tried() {
        let (root, places) = layout();
        let err = find_in(DataKind::Scenarios, None, None, &places).unwrap_err();
        let DataDirError::NotFound { kind, tried } = &err else {
            panic!("{err}");
        };
        assert_eq!(*kind, DataKind::Scenarios);
        let work = root.path().join("work");
        let expected = [
            "$FLEET_SCENARIOS_DIR (not set)".to_string(),
            format!(
                "{} (current directory)",
                work.join("sim/scenarios").display()
            ),
            format!("{} (current directory)", work.join("scenarios").display()),
            format!(
                "{} (user data directory)",
                root.path().join("data/scenarios").display()
            ),
        ];
        assert_eq!(tried.as_slice(), expected.as_slice());
        let msg = err.to_string();
        for place in &expected {
            assert!(msg.contains(place.as_str()), "{msg}");
        }

        let bare = Places::default();
        let err = find_in(DataKind::Models, None, None, &bare).unwrap_err();
        assert!(err.to_string().contains("no user data directory"), "{err}");
    }

    #[test]
    fn a_file_is_not_a_folder() {
        let (root, places) = layout();
        std::fs::write(root.path().join("work/models"), b"not a folder").unwrap();
        assert!(find_in(DataKind::Models, None, None, &places).is_err());
    }
}
