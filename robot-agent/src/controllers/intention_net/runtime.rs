//! Finding and loading the ONNX Runtime shared library, once per process.
//!
//! `ort` is built with `load-dynamic`: nothing is downloaded or linked at build time, and the
//! library is opened at run time from, in this order:
//!
//! 1. `ORT_DYLIB_PATH`, if set and non-empty (an error if that file does not exist: a wrong
//!    explicit setting must not silently fall back to another library);
//! 2. `<root>/.venv/lib/python3*/site-packages/onnxruntime/capi/libonnxruntime.so*`, the PyPI
//!    `onnxruntime` wheel that `bash scripts/setup.sh` installs, where `<root>` is tried as
//!    every ancestor of the current directory, then every ancestor of the running executable,
//!    then the user's data directory ([`protocol::data_dirs::user_data_dir`], e.g.
//!    `~/.local/share/intention-fleet/.venv/…`). No path of the source tree the binary was
//!    built from is compiled in: an installed agent finds the library the same way anywhere.
//!
//! Otherwise loading fails with [`RuntimeError`], which says to run `bash scripts/setup.sh` or
//! set `ORT_DYLIB_PATH`.

use std::ffi::OsString;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use ort::environment::Environment;

/// The environment variable that names the library explicitly.
pub const ORT_DYLIB_ENV: &str = "ORT_DYLIB_PATH";

/// The ONNX Runtime version that scripts/setup.sh installs (ort 2.0.0-rc.15 speaks 1.31).
pub const ONNXRUNTIME_VERSION: &str = "1.31.1";

const SETUP_HINT: &str = "run `bash scripts/setup.sh` in the repository root (it installs the \
     PyPI onnxruntime wheel into .venv) or set ORT_DYLIB_PATH to a libonnxruntime.so of ONNX \
     Runtime >= 1.24";

/// Why ONNX Runtime is not available.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum RuntimeError {
    #[error("ONNX Runtime library not found: ORT_DYLIB_PATH={path} does not exist; {SETUP_HINT}")]
    EnvPathMissing { path: String },
    #[error(
        "ONNX Runtime library not found: ORT_DYLIB_PATH is not set and there is no \
         .venv/lib/python3*/site-packages/onnxruntime/capi/libonnxruntime.so* under any of \
         [{searched}]; {SETUP_HINT}"
    )]
    NotFound { searched: String },
    #[error("cannot load ONNX Runtime from {path}: {reason}; {SETUP_HINT}")]
    Load { path: String, reason: String },
    #[error("cannot create the ONNX Runtime environment: {0}")]
    Environment(String),
}

/// Where the agent looks for a `.venv`, in order (see the module docs).
#[must_use]
pub fn default_search_roots() -> Vec<PathBuf> {
    let mut roots: Vec<PathBuf> = Vec::new();
    let mut push_ancestors = |start: &Path| {
        for dir in start.ancestors() {
            if !roots.iter().any(|r| r == dir) {
                roots.push(dir.to_path_buf());
            }
        }
    };
    if let Ok(cwd) = std::env::current_dir() {
        push_ancestors(&cwd);
    }
    if let Some(exe_dir) = std::env::current_exe()
        .ok()
        .and_then(|exe| exe.parent().map(Path::to_path_buf))
    {
        push_ancestors(&exe_dir);
    }
    if let Some(data) = protocol::data_dirs::user_data_dir() {
        if !roots.contains(&data) {
            roots.push(data);
        }
    }
    roots
}

/// The wheel's library inside `<root>/.venv`, if there is one. The newest Python directory and
/// the most specific file name win so the choice does not depend on directory order.
#[must_use]
pub fn venv_library_in(root: &Path) -> Option<PathBuf> {
    let lib = root.join(".venv").join("lib");
    let mut pythons: Vec<PathBuf> = std::fs::read_dir(&lib)
        .ok()?
        .filter_map(Result::ok)
        .filter(|e| e.file_name().to_string_lossy().starts_with("python3"))
        .map(|e| e.path())
        .collect();
    pythons.sort();
    pythons.into_iter().rev().find_map(|py| {
        let capi = py.join("site-packages/onnxruntime/capi");
        let mut libs: Vec<PathBuf> = std::fs::read_dir(&capi)
            .ok()?
            .filter_map(Result::ok)
            .filter(|e| {
                e.file_name()
                    .to_string_lossy()
                    .starts_with("libonnxruntime.so")
                    && e.path().is_file()
            })
            .map(|e| e.path())
            .collect();
        libs.sort();
        libs.pop()
    })
}

/// Picks the library from an `ORT_DYLIB_PATH` value (`None` or empty: unset) and search roots.
///
/// # Errors
/// [`RuntimeError::EnvPathMissing`] or [`RuntimeError::NotFound`], both saying what to do.
pub fn find_library(
    env_value: Option<OsString>,
    roots: &[PathBuf],
) -> Result<PathBuf, RuntimeError> {
    if let Some(value) = env_value.filter(|v| !v.is_empty()) {
        let path = PathBuf::from(value);
        return if path.is_file() {
            Ok(path)
        } else {
            Err(RuntimeError::EnvPathMissing {
                path: path.display().to_string(),
            })
        };
    }
    roots
        .iter()
        .find_map(|root| venv_library_in(root))
        .ok_or_else(|| RuntimeError::NotFound {
            searched: roots
                .iter()
                .map(|r| r.display().to_string())
                .collect::<Vec<_>>()
                .join(", "),
        })
}

struct Loaded {
    path: PathBuf,
    environment: Environment,
}

static RUNTIME: OnceLock<Result<Loaded, RuntimeError>> = OnceLock::new();

fn load() -> Result<Loaded, RuntimeError> {
    let path = find_library(std::env::var_os(ORT_DYLIB_ENV), &default_search_roots())?;
    let builder = ort::init_from(&path).map_err(|e| RuntimeError::Load {
        path: path.display().to_string(),
        reason: e.to_string(),
    })?;
    let environment = builder
        .with_name("robot-agent")
        .with_telemetry(false)
        .build()
        .map_err(|e| RuntimeError::Environment(e.to_string()))?;
    Ok(Loaded { path, environment })
}

/// The process-wide ONNX Runtime environment, loading the library on first use. A failure is
/// remembered: the library cannot be half-loaded twice.
///
/// # Errors
/// [`RuntimeError`] saying why and what to do.
pub fn environment() -> Result<&'static Environment, RuntimeError> {
    match RUNTIME.get_or_init(load) {
        Ok(loaded) => Ok(&loaded.environment),
        Err(e) => Err(e.clone()),
    }
}

/// The library the process loaded, once [`environment`] succeeded.
#[must_use]
pub fn loaded_library() -> Option<&'static Path> {
    match RUNTIME.get() {
        Some(Ok(loaded)) => Some(&loaded.path),
        _ => None,
    }
}
