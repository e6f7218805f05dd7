//! The library's error type. Every variant names the input or the Vulkan call it is about, so
//! `main` can print the whole cause chain and choose the exit code (2 for bad input).

use std::path::PathBuf;

/// Errors surfaced by the library.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// The user's input (file, config value, flag) is wrong; exit code 2.
    #[error("{input}: {message}")]
    Input { input: String, message: String },
    /// An I/O failure on a named path.
    #[error("{path}: {source}")]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A Vulkan call failed.
    #[error("Vulkan: {call} failed: {result:?}")]
    Vulkan { call: &'static str, result: ash::vk::Result },
    /// The GPU back end cannot run (no loader, no device, missing feature).
    #[error("GPU: {0}")]
    Gpu(String),
    /// HDF5 writing/reading failed for a named file.
    #[error("{path}: HDF5: {message}")]
    Hdf5 { path: PathBuf, message: String },
    /// The run was stopped by a signal (SIGINT, SIGTERM) between frames; the sequence in
    /// flight was discarded. `main` exits with 128 + the signal number.
    #[error("stopped by signal {signal}; the sequence in flight was discarded, every earlier one is complete")]
    Interrupted { signal: i32 },
    /// Anything else that is a failure of pedscan itself, not of the input.
    #[error("{0}")]
    Internal(String),
}

impl Error {
    /// A bad-input error naming `input`.
    pub fn input(input: impl std::fmt::Display, message: impl std::fmt::Display) -> Self {
        Error::Input { input: input.to_string(), message: message.to_string() }
    }
    /// An I/O error on `path`.
    pub fn io(path: impl Into<PathBuf>, source: std::io::Error) -> Self {
        Error::Io { path: path.into(), source }
    }
    /// True when the user's input is at fault (exit code 2).
    pub fn is_input(&self) -> bool {
        matches!(self, Error::Input { .. })
    }
}

/// Shorthand for results of the library.
pub type Result<T, E = Error> = std::result::Result<T, E>;

/// The most of one error line printed (`clipped`): a message echoing a hostile input (a
/// 100 MB string in a config, TOML nested thousands deep) stays readable.
pub const MAX_MESSAGE_BYTES: usize = 4096;

/// `text` within [`MAX_MESSAGE_BYTES`]: its first and last halves of that, cut at character
/// boundaries, saying how much was left out between them (a parser's reason comes last, after
/// the echoed input).
pub fn clipped(text: &str) -> std::borrow::Cow<'_, str> {
    if text.len() <= MAX_MESSAGE_BYTES {
        return text.into();
    }
    let half = MAX_MESSAGE_BYTES / 2;
    let head = (0..=half).rev().find(|&i| text.is_char_boundary(i)).unwrap_or(0);
    let tail = (text.len() - half..text.len()).find(|&i| text.is_char_boundary(i)).unwrap_or(text.len());
    format!("{} ... ({} bytes left out) ... {}", &text[..head], tail - head, &text[tail..]).into()
}

#[cfg(test)]
mod tests {
    #[test]
    fn long_messages_keep_their_head_and_tail_cut_at_character_boundaries() {
        assert_eq!(super::clipped("short"), "short");
        let long = format!("start {} reason", "é".repeat(5000));
        let c = super::clipped(&long);
        assert!(c.len() < super::MAX_MESSAGE_BYTES + 60, "{}", c.len());
        let (head, rest) = c.split_once(" ... (").unwrap();
        let (gap, tail) = rest.split_once(" bytes left out) ... ").unwrap();
        assert!(long.starts_with(head) && long.ends_with(tail) && tail.ends_with(" reason") && head.starts_with("start "));
        assert_eq!(head.len() + gap.parse::<usize>().unwrap() + tail.len(), long.len());
    }
}
