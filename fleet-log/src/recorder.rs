//! [`Recorder`]: a [`LogWriter`] on its own thread, for real-time nodes whose loops must not
//! wait for compression or the disk.

use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::thread::JoinHandle;

use protocol::CameraFrame;

use crate::reader::LogMessage;
use crate::writer::{LogOptions, LogWriter};
use crate::LogError;

enum Item {
    Message(Box<LogMessage>),
    /// Compressed on the recorder's thread.
    Camera(Box<CameraFrame>),
}

/// Records messages in the order [`Self::record`] is called, on a background thread.
#[derive(Debug)]
pub struct Recorder {
    path: PathBuf,
    camera: bool,
    tx: Option<mpsc::Sender<Item>>,
    thread: Option<JoinHandle<Result<PathBuf, LogError>>>,
}

impl Recorder {
    /// Creates `path.partial` now (so a bad path fails at start-up) and starts the thread.
    ///
    /// # Errors
    /// [`LogError::Io`] naming the file when it cannot be created or the thread not started.
    pub fn start(path: &Path, options: LogOptions) -> Result<Self, LogError> {
        let mut writer = LogWriter::create(path, options)?;
        let (tx, rx) = mpsc::channel::<Item>();
        let thread = std::thread::Builder::new()
            .name("fleet-log".into())
            .spawn(move || {
                for item in rx {
                    match item {
                        Item::Message(m) => writer.write(&m)?,
                        Item::Camera(frame) => writer.camera(&frame)?,
                    }
                }
                writer.finish()
            })
            .map_err(|e| LogError::io(path, "start the recorder thread for", e))?;
        Ok(Self {
            path: path.to_path_buf(),
            camera: options.camera,
            tx: Some(tx),
            thread: Some(thread),
        })
    }

    /// The file the log ends up in.
    #[must_use]
    pub fn path(&self) -> &Path {
        &self.path
    }

    fn send(&mut self, item: Item) {
        let Some(tx) = &self.tx else { return };
        if tx.send(item).is_err() {
            // The thread ended with an error; `finish` reports it.
            tracing::warn!(path = %self.path.display(), "the log recorder stopped; no more messages are recorded");
            self.tx = None;
        }
    }

    /// Queues one message.
    pub fn record(&mut self, message: LogMessage) {
        self.send(Item::Message(Box::new(message)));
    }

    /// Queues one camera frame (dropped at once unless [`LogOptions::camera`] is set).
    pub fn record_camera(&mut self, frame: &CameraFrame) {
        if self.camera {
            self.send(Item::Camera(Box::new(frame.clone())));
        }
    }

    /// Writes what is queued, finishes the log and renames it into place.
    ///
    /// # Errors
    /// The first [`LogError`] of the thread, naming the file.
    pub fn finish(mut self) -> Result<PathBuf, LogError> {
        self.tx = None;
        match self.thread.take().map(JoinHandle::join) {
            Some(Ok(result)) => result,
            Some(Err(_)) => Err(LogError::Recorder {
                path: self.path.clone(),
                reason: "it panicked".into(),
            }),
            None => Ok(self.path.clone()),
        }
    }
}

impl Drop for Recorder {
    fn drop(&mut self) {
        // Not finished: let the thread write the queue and rename the log (its error, if any,
        // goes to the log output since nobody can receive it any more).
        self.tx = None;
        if let Some(thread) = self.thread.take() {
            match thread.join() {
                Ok(Ok(path)) => tracing::info!(path = %path.display(), "log written"),
                Ok(Err(e)) => tracing::warn!("{e}"),
                Err(_) => tracing::warn!(path = %self.path.display(), "the log recorder panicked"),
            }
        }
    }
}
