//! Progress bars for long work: on stderr, only when it is a terminal (never in CI logs or
//! pipes), and only once the work has run for a second, so quick commands print nothing.

use indicatif::{ProgressBar, ProgressDrawTarget, ProgressStyle};
use std::time::Duration;

/// Work shorter than this shows no bar.
const SHOW_AFTER: Duration = Duration::from_secs(1);

/// A bar of `len` steps drawn with `template` (indicatif syntax; `{eta}` gives the time
/// left). Hidden when `enabled` is false; otherwise it appears after [`SHOW_AFTER`] if the
/// work is still running and stderr is a terminal. Finish it with `finish_and_clear`.
pub fn bar(enabled: bool, len: u64, template: &str) -> ProgressBar {
    let pb = ProgressBar::with_draw_target(Some(len), ProgressDrawTarget::hidden());
    if !enabled {
        return pb;
    }
    if let Ok(style) = ProgressStyle::with_template(template) {
        pb.set_style(style.progress_chars("=> "));
    }
    let weak = pb.downgrade();
    std::thread::spawn(move || {
        std::thread::sleep(SHOW_AFTER);
        if let Some(pb) = weak.upgrade().filter(|pb| !pb.is_finished()) {
            // `stderr()` draws nothing when stderr is not a terminal.
            pb.set_draw_target(ProgressDrawTarget::stderr());
        }
    });
    pb
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn disabled_and_short_bars_stay_hidden() {
        let pb = bar(false, 10, "{bar}");
        pb.inc(5);
        assert!(pb.is_hidden());
        let pb = bar(true, 10, "{bar}");
        pb.inc(10);
        assert!(pb.is_hidden(), "shown before a second had passed");
        pb.finish_and_clear();
    }
}
