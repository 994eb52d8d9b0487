//! Logging setup shared by the dyfos binaries (`dyfosd`, `dyfos-rover`,
//! `dyfos-viewer`).
//!
//! ```no_run
//! dyfos_client::logging::init();
//! tracing::info!("the log goes to stderr; RUST_LOG=debug shows more");
//! ```
//!
//! A process that runs for weeks must not let a peer decide how much it writes: a
//! client that misbehaves in a loop, or iceoryx2 warning about every reply towards
//! a dead client, would otherwise fill the log. So at `info` and above each kind of
//! line (its call site and its text with the numbers taken out) is written at most
//! [`BURST`] times per [`WINDOW`]; the rest are counted, and once the window is over
//! one line says how many were left out, e.g. `… 128 more in the last 10 s like:
//! rendezvous receive failed: ExceedsMaxBorrows`. Every field is cut at
//! [`FIELD_LIMIT`] bytes (iceoryx2 prints a port's whole state, about 5 KB, with each
//! of its warnings). `debug` and `trace`, for troubleshooting, log everything.
//! [`counters`] tells how many lines were seen and left out (`dyfos stats` shows them).

use std::collections::HashMap;
use std::fmt::Write as _;
use std::hash::{Hash, Hasher};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, Instant};
use tracing::field::{Field, Visit};
use tracing::{Event, Level, Subscriber};
use tracing_subscriber::EnvFilter;
use tracing_subscriber::layer::{Context, Layer};
use tracing_subscriber::prelude::*;

/// Lines of one kind written per window before the rest are only counted.
pub const BURST: u32 = 5;

/// The window over which [`BURST`] applies.
pub const WINDOW: Duration = Duration::from_secs(10);

/// Most bytes of one field's value written; the rest is replaced by `…`.
pub const FIELD_LIMIT: usize = 400;

/// Most kinds of line counted at once; lines of further kinds share one count, so
/// lines that differ in every letter cannot grow the limiter's table either.
const MAX_KINDS: usize = 1024;

/// The target under which iceoryx2's own log lines arrive.
const ICEORYX_TARGET: &str = "iceoryx2_bb_loggers::tracing";

/// What the log has seen since the process started.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LogCounters {
    /// Warnings and errors (written or not).
    pub warnings: u64,
    /// Of those, iceoryx2's own (e.g. its warning for each notification towards a
    /// client that died).
    pub ipc_warnings: u64,
    /// Lines at `info` and above left out by the rate limit.
    pub suppressed: u64,
}

static WARNINGS: AtomicU64 = AtomicU64::new(0);
static IPC_WARNINGS: AtomicU64 = AtomicU64::new(0);
static SUPPRESSED: AtomicU64 = AtomicU64::new(0);

/// The counts since the process started (zero where [`init`] was not called).
pub fn counters() -> LogCounters {
    LogCounters {
        warnings: WARNINGS.load(Ordering::Relaxed),
        ipc_warnings: IPC_WARNINGS.load(Ordering::Relaxed),
        suppressed: SUPPRESSED.load(Ordering::Relaxed),
    }
}

/// Logs to stderr through `tracing`, filtered by `RUST_LOG` (default `info`), in
/// colour only on a terminal, rate-limited as the module says. iceoryx2 logs through
/// `tracing` too (its `tracing` feature); its own level comes from `IOX2_LOG_LEVEL`
/// (default `Warn`), since at `info` it reports every port it opens. A second call
/// does nothing.
pub fn init() {
    init_with("info", &[]);
}

/// [`init`] with `default` as the filter when `RUST_LOG` is unset, and the `debug`
/// lines of the targets starting with one of `limited` always shown but
/// rate-limited like the rest: for a library that reports what a peer did (a
/// refused login) only at `debug`.
pub fn init_with(default: &str, limited: &'static [&'static str]) {
    let _ = LIMITED_DEBUG.set(limited);
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(default));
    let filter = limited.iter().fold(filter, |f, target| match format!("{target}=debug").parse() {
        Ok(directive) => f.add_directive(directive),
        Err(_) => f,
    });
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let fields = tracing_subscriber::fmt::format::debug_fn(|w, field, value| {
        let mut text = String::new();
        let _ = write!(text, "{value:?}");
        cut(&mut text, FIELD_LIMIT);
        if field.name() == "message" { write!(w, "{text}") } else { write!(w, "{field}={text}") }
    })
    .delimited(" ");
    let format = tracing_subscriber::fmt::layer().with_writer(std::io::stderr).with_ansi(ansi).fmt_fields(fields);
    let installed = tracing_subscriber::registry().with(filter).with(limiter().clone()).with(format).try_init();
    if installed.is_ok() {
        // Summaries are written from a thread of their own, outside any log call.
        let _ = std::thread::Builder::new().name("dyfos-log-summary".into()).spawn(|| {
            loop {
                std::thread::sleep(Duration::from_secs(1));
                limiter().flush(Instant::now());
            }
        });
    }
    iceoryx2::prelude::set_log_level_from_env_or(iceoryx2::prelude::LogLevel::Warn);
}

/// Writes the summaries of every window that is over, and of those still open, so
/// that nothing counted is left unsaid (call before a process exits).
pub fn flush() {
    limiter().flush(Instant::now() + WINDOW);
}

/// Targets whose `debug` lines are rate-limited too (see [`init_with`]).
static LIMITED_DEBUG: OnceLock<&'static [&'static str]> = OnceLock::new();

fn limiter() -> &'static RateLimit {
    static LIMITER: OnceLock<RateLimit> = OnceLock::new();
    LIMITER.get_or_init(RateLimit::default)
}

/// Truncates `text` to at most `limit` bytes, at a character boundary, marking the cut.
fn cut(text: &mut String, limit: usize) {
    if text.len() > limit {
        let mut end = limit;
        while !text.is_char_boundary(end) {
            end -= 1;
        }
        text.truncate(end);
        text.push('…');
    }
}

/// The kind of a line: its call site and its message with every digit run made
/// one `#`, so that ids and counts do not make each line a kind of its own.
fn kind_of(event: &Event<'_>, message: &str) -> u64 {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    event.metadata().callsite().hash(&mut h);
    let mut in_digits = false;
    for c in message.chars() {
        let digit = c.is_ascii_digit();
        if !(digit && in_digits) {
            (if digit { '#' } else { c }).hash(&mut h);
        }
        in_digits = digit;
    }
    h.finish()
}

struct Message(String);

impl Visit for Message {
    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            let _ = write!(self.0, "{value:?}");
            cut(&mut self.0, FIELD_LIMIT);
        }
    }
}

/// One kind's count in its current window.
struct Window {
    start: Instant,
    written: u32,
    left_out: u64,
    level: Level,
    sample: String,
}

/// The rate limit: a `tracing` layer whose `event_enabled` drops a line past its
/// kind's burst.
#[derive(Default, Clone)]
struct RateLimit {
    windows: std::sync::Arc<Mutex<HashMap<u64, Window>>>,
}

impl RateLimit {
    /// Whether a line of this kind may be written at `now`; counts it if not.
    fn admit(&self, kind: u64, level: Level, message: impl FnOnce() -> String, now: Instant) -> bool {
        let mut windows = self.windows.lock().unwrap_or_else(|p| p.into_inner());
        let kind = if windows.len() >= MAX_KINDS && !windows.contains_key(&kind) { 0 } else { kind };
        let w = windows.entry(kind).or_insert_with(|| Window {
            start: now,
            written: 0,
            left_out: 0,
            level,
            sample: String::new(),
        });
        if now.duration_since(w.start) >= WINDOW && w.left_out == 0 {
            // A new window; one with lines left out restarts when its summary is written.
            *w = Window { start: now, written: 0, left_out: 0, level, sample: String::new() };
        }
        if w.written < BURST {
            w.written += 1;
            return true;
        }
        if w.left_out == 0 {
            w.sample = message();
        }
        w.left_out += 1;
        SUPPRESSED.fetch_add(1, Ordering::Relaxed);
        false
    }

    /// Writes a summary for every window over at `now` that left lines out.
    fn flush(&self, now: Instant) {
        let due: Vec<(Level, u64, String)> = {
            let mut windows = self.windows.lock().unwrap_or_else(|p| p.into_inner());
            let mut due = Vec::new();
            windows.retain(|_, w| {
                if now.duration_since(w.start) < WINDOW {
                    return true;
                }
                if w.left_out > 0 {
                    due.push((w.level, w.left_out, std::mem::take(&mut w.sample)));
                }
                false
            });
            due
        };
        // Written after the lock is released: these lines pass through `admit` too.
        let secs = WINDOW.as_secs();
        for (level, count, sample) in due {
            match level {
                Level::ERROR => tracing::error!("… {count} more in the last {secs} s like: {sample}"),
                Level::WARN => tracing::warn!("… {count} more in the last {secs} s like: {sample}"),
                _ => tracing::info!("… {count} more in the last {secs} s like: {sample}"),
            }
        }
    }
}

impl<S: Subscriber> Layer<S> for RateLimit {
    fn event_enabled(&self, event: &Event<'_>, _ctx: Context<'_, S>) -> bool {
        let meta = event.metadata();
        let level = *meta.level();
        let limited = || LIMITED_DEBUG.get().is_some_and(|t| t.iter().any(|t| meta.target().starts_with(t)));
        if level > Level::INFO && !(level == Level::DEBUG && limited()) {
            return true; // debug and trace: troubleshooting, everything
        }
        if level <= Level::WARN {
            WARNINGS.fetch_add(1, Ordering::Relaxed);
            if meta.target() == ICEORYX_TARGET {
                IPC_WARNINGS.fetch_add(1, Ordering::Relaxed);
            }
        }
        let mut message = Message(String::new());
        event.record(&mut message);
        let kind = kind_of(event, &message.0);
        self.admit(kind, level, || message.0.clone(), Instant::now())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_kind_is_written_burst_times_per_window_then_summarised() {
        let limit = RateLimit::default();
        let t0 = Instant::now();
        let admitted = (0..100).filter(|_| limit.admit(1, Level::WARN, || "flood".into(), t0)).count();
        assert_eq!(admitted, BURST as usize);
        // Another kind is not held back by the first.
        assert!(limit.admit(2, Level::WARN, || "other".into(), t0));
        let left_out = limit.windows.lock().unwrap()[&1].left_out;
        assert_eq!(left_out, 100 - u64::from(BURST));
        // Before the window is over nothing is summarised; after, the window goes.
        limit.flush(t0 + WINDOW / 2);
        assert!(limit.windows.lock().unwrap().contains_key(&1));
        limit.flush(t0 + WINDOW);
        assert!(!limit.windows.lock().unwrap().contains_key(&1));
        // A new window writes again.
        assert!(limit.admit(1, Level::WARN, || "flood".into(), t0 + WINDOW));
    }

    /// iceoryx2's own lines (its warning for each notification towards a dead
    /// client's listener) are counted and held back like ours.
    #[test]
    fn iceoryx2_warnings_are_counted_and_held_back() {
        use std::sync::atomic::AtomicUsize;
        struct Written(std::sync::Arc<AtomicUsize>);
        impl<S: Subscriber> Layer<S> for Written {
            fn on_event(&self, _: &Event<'_>, _: Context<'_, S>) {
                self.0.fetch_add(1, Ordering::Relaxed);
            }
        }
        let written = std::sync::Arc::new(AtomicUsize::new(0));
        let subscriber =
            tracing_subscriber::registry().with(RateLimit::default()).with(Written(std::sync::Arc::clone(&written)));
        let before = counters();
        tracing::subscriber::with_default(subscriber, || {
            for id in 0..200u64 {
                tracing::warn!(target: "iceoryx2_bb_loggers::tracing", origin = "Notifier { .. }", "Inconsistency detected! No connection but listener id: {id}.");
            }
        });
        let after = counters();
        assert_eq!(written.load(Ordering::Relaxed), BURST as usize);
        assert_eq!(after.ipc_warnings - before.ipc_warnings, 200);
        assert!(after.suppressed - before.suppressed >= 200 - u64::from(BURST));
    }

    #[test]
    fn long_fields_are_cut_at_a_character_boundary() {
        let mut text = "é".repeat(FIELD_LIMIT);
        cut(&mut text, FIELD_LIMIT);
        assert!(text.len() <= FIELD_LIMIT + '…'.len_utf8());
        assert!(text.ends_with('…'));
        let mut short = "short".to_string();
        cut(&mut short, FIELD_LIMIT);
        assert_eq!(short, "short");
    }
}
