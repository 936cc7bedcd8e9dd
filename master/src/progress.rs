//! Progress display for long work (`indicatif`), on stderr; hidden when stderr is not a
//! terminal, so scripts and tests see clean output.

use indicatif::{ProgressBar, ProgressStyle};
use std::time::Duration;

/// A spinner with a message, for work that cannot report how far it is (parsing a file).
pub fn spinner(msg: impl Into<String>) -> ProgressBar {
    let pb = ProgressBar::new_spinner();
    pb.set_style(ProgressStyle::with_template("{spinner} {msg} ({elapsed})").expect("valid template"));
    pb.set_message(msg.into());
    pb.enable_steady_tick(Duration::from_millis(120));
    pb
}

/// A bar over `total` items.
pub fn bar(total: u64, msg: impl Into<String>) -> ProgressBar {
    styled(total, msg, "{msg} [{bar:30}] {human_pos}/{human_len} ({per_sec}, {eta})")
}

/// A bar over `total` bytes of a file.
pub fn bytes(total: u64, msg: impl Into<String>) -> ProgressBar {
    styled(total, msg, "{msg} [{bar:30}] {bytes}/{total_bytes} ({bytes_per_sec}, {eta})")
}

fn styled(total: u64, msg: impl Into<String>, template: &str) -> ProgressBar {
    let pb = ProgressBar::new(total);
    pb.set_style(ProgressStyle::with_template(template).expect("valid template").progress_chars("=> "));
    pb.set_message(msg.into());
    pb
}
