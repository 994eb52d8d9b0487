//! Logging setup shared by the dyfos binaries (`dyfosd`, `dyfos-rover`,
//! `dyfos-viewer`, `dyfos-link`).
//!
//! ```no_run
//! dyfos_process::logging::init();
//! tracing::info!("the log goes to stderr; RUST_LOG=debug shows more");
//! dyfos_process::logging::flush(); // before exiting: the last window's summary
//! ```
//!
//! A process that runs for weeks must not let a peer decide how much it writes: a
//! client that misbehaves in a loop, iceoryx2 warning about every reply towards a
//! dead client, or a library quoting every garbage frame a stranger sends would
//! otherwise fill the log. So at `info` and above
//! - each kind of line (its call site and its text with every number, and every word
//!   with a digit in it, taken out) is written at most [`BURST`] times per [`WINDOW`];
//! - all of them together write at most [`BUDGET`] bytes per window, however many
//!   kinds there are; past it, only the first line of each call site (a place in
//!   the code, whatever its text) is written, so that the process still says what
//!   it did itself (`link stopped …`) while a stranger's garbage fills the budget;
//! - the rest are counted, and once the window is over a few lines say how many were
//!   left out, e.g. `… 128 more in the last 10 s like: rendezvous receive failed:
//!   ExceedsMaxBorrows`: the [`SUMMARIES`] most frequent kinds one by one, the others
//!   in one line, and one more line if the byte budget was reached;
//! - every field is cut at [`FIELD_LIMIT`] bytes (iceoryx2 prints a port's whole
//!   state, about 5 KB, with each of its warnings).
//!
//! So a window writes at most [`BUDGET`] bytes, one line per call site that spoke
//! past it, and [`SUMMARIES`] + 2 summary lines.
//! `debug` and `trace`, for troubleshooting, log everything. [`counters`] tells how
//! many lines were seen and left out (`dyfos stats` shows them); [`flush`] writes the
//! summary of the window still open, for a process about to exit.
//!
//! A [`Tally`] counts lines a library writes below the log's level (Zenoh's line for
//! each handshake it gave up on, say) without writing them, for the process to
//! report in its own words.

use std::collections::HashMap;
use std::fmt::Write as _;
use std::hash::{Hash, Hasher};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Mutex, OnceLock};
use std::time::{Duration, Instant};
use tracing::field::{Field, Visit};
use tracing::{Event, Level, Metadata, Subscriber};
use tracing_subscriber::EnvFilter;
use tracing_subscriber::layer::{Context, Layer};
use tracing_subscriber::prelude::*;

/// Lines of one kind written per window before the rest are only counted.
pub const BURST: u32 = 5;

/// The window over which [`BURST`] and [`BUDGET`] apply.
pub const WINDOW: Duration = Duration::from_secs(10);

/// Most bytes of one field's value written; the rest is replaced by `…`.
pub const FIELD_LIMIT: usize = 400;

/// Most bytes the rate-limited lines of all kinds together write per [`WINDOW`]
/// (as estimated before writing: fields, target and the timestamp and level); past
/// it, lines are only counted until the window is over.
pub const BUDGET: usize = 16 * 1024;

/// Kinds whose left-out lines get a summary line each per window; the others share one.
pub const SUMMARIES: usize = 5;

/// Most kinds of line counted at once; lines of further kinds share one count, so
/// lines that differ in every letter cannot grow the limiter's table either.
const MAX_KINDS: usize = 1024;

/// Bytes a written line takes besides its target and fields: timestamp, level,
/// separators, newline.
const LINE_OVERHEAD: usize = 40;

/// The target under which iceoryx2's own log lines arrive.
const ICEORYX_TARGET: &str = "iceoryx2_bb_loggers::tracing";

/// The target of the limiter's own summaries, which it lets through: they are
/// bounded by construction (at most [`SUMMARIES`] + 2 per window).
const SUMMARY_TARGET: &str = "dyfos::log";

/// What the log has seen since the process started.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct LogCounters {
    /// Warnings and errors (written or not).
    pub warnings: u64,
    /// Of those, iceoryx2's own (e.g. its warning for each notification towards a
    /// client that died).
    pub ipc_warnings: u64,
    /// Lines at `info` and above left out by the rate limit or the byte budget.
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

/// One kind of line a library writes, counted rather than written: those of
/// `target` (or a module under it) at exactly `level` whose message starts with
/// `starts_with`. A tally sees its lines whatever `RUST_LOG` says; they are written
/// too only if `RUST_LOG` asks for them.
///
/// ```
/// use dyfos_process::logging::Tally;
/// static TIMED_OUT: Tally =
///     Tally::new("zenoh_transport::unicast::manager", tracing::Level::DEBUG, "Failed to accept link");
/// assert_eq!(TIMED_OUT.count(), 0);
/// ```
#[derive(Debug)]
pub struct Tally {
    target: &'static str,
    level: Level,
    starts_with: &'static str,
    count: AtomicU64,
    last: Mutex<String>,
}

impl Tally {
    /// A tally of the lines of `target` at `level` starting with `starts_with`.
    pub const fn new(target: &'static str, level: Level, starts_with: &'static str) -> Self {
        Tally { target, level, starts_with, count: AtomicU64::new(0), last: Mutex::new(String::new()) }
    }

    /// Lines counted since the process started.
    pub fn count(&self) -> u64 {
        self.count.load(Ordering::Relaxed)
    }

    /// The last line counted (cut at [`FIELD_LIMIT`]; empty before the first).
    pub fn last(&self) -> String {
        self.last.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }

    fn covers(&self, meta: &Metadata<'_>) -> bool {
        *meta.level() == self.level && meta.target().starts_with(self.target)
    }

    fn count_line(&self, message: &str) {
        if message.starts_with(self.starts_with) {
            self.count.fetch_add(1, Ordering::Relaxed);
            message.clone_into(&mut self.last.lock().unwrap_or_else(|p| p.into_inner()));
        }
    }
}

/// Logs to stderr through `tracing`, filtered by `RUST_LOG` (default `info`), in
/// colour only on a terminal, rate-limited as the module says. iceoryx2 logs through
/// `tracing` too (its `tracing` feature); its own level comes from `IOX2_LOG_LEVEL`
/// (default `Warn`), since at `info` it reports every port it opens. A second call
/// does nothing.
pub fn init() {
    init_with("info", &[], &[]);
}

/// [`init`] with `default` as the filter when `RUST_LOG` is unset; the `debug`
/// lines of the targets starting with one of `limited` always shown but
/// rate-limited like the rest (for a library that reports what a peer did, a
/// refused login, only at `debug`); and the lines of `tallies` counted.
pub fn init_with(default: &str, limited: &'static [&'static str], tallies: &'static [&'static Tally]) {
    let _ = LIMITED_DEBUG.set(limited);
    let filter = EnvFilter::try_from_default_env().unwrap_or_else(|_| EnvFilter::new(default));
    let filter = limited.iter().fold(filter, |f, target| match format!("{target}=debug").parse() {
        Ok(directive) => f.add_directive(directive),
        Err(_) => f,
    });
    let ansi = std::io::IsTerminal::is_terminal(&std::io::stderr());
    let installed = subscriber(filter, limiter().clone(), tallies, std::io::stderr, ansi).try_init();
    if installed.is_ok() {
        // Summaries are written from a thread of their own, outside any log call.
        let _ = std::thread::Builder::new().name("dyfos-log-summary".into()).spawn(|| {
            loop {
                std::thread::sleep(Duration::from_secs(1));
                limiter().flush(Instant::now(), false);
            }
        });
    }
    iceoryx2_log::set_log_level_from_env_or(iceoryx2_log::LogLevel::Warn);
}

/// Writes the summaries of the windows that are over, and of the one still open,
/// so that nothing counted is left unsaid (call before a process exits).
pub fn flush() {
    limiter().flush(Instant::now(), true);
}

/// The log: what `filter` asks for, limited by `limit`, written to `writer`; and
/// the tallies' lines, counted. Per-layer filters keep the two apart (the tallies
/// come first, so that a line the limiter holds back is counted all the same).
fn subscriber<W>(
    filter: EnvFilter,
    limit: RateLimit,
    tallies: &'static [&'static Tally],
    writer: W,
    ansi: bool,
) -> impl Subscriber + Send + Sync + 'static
where
    W: for<'w> tracing_subscriber::fmt::MakeWriter<'w> + Send + Sync + 'static,
{
    let fields = tracing_subscriber::fmt::format::debug_fn(|w, field, value| {
        let mut text = String::new();
        let _ = write!(text, "{value:?}");
        cut(&mut text, FIELD_LIMIT);
        if field.name() == "message" { write!(w, "{text}") } else { write!(w, "{field}={text}") }
    })
    .delimited(" ");
    let format = tracing_subscriber::fmt::layer().with_writer(writer).with_ansi(ansi).fmt_fields(fields);
    let written = limit.and_then(format).with_filter(filter);
    let tallied = tracing_subscriber::filter::Targets::new().with_targets(tallies.iter().map(|t| (t.target, t.level)));
    tracing_subscriber::registry().with(written).with(Tallies(tallies).with_filter(tallied))
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

/// The call site of a line, and its kind: the call site and its message with
/// every word that holds a digit (a number, a hex id, a payload) made one `#`, so
/// that ids, counts and quoted bytes do not make each line a kind of its own.
fn site_and_kind(event: &Event<'_>, message: &str) -> (u64, u64) {
    let mut h = std::collections::hash_map::DefaultHasher::new();
    event.metadata().callsite().hash(&mut h);
    let site = h.finish();
    hash_text(message, &mut h);
    (site, h.finish())
}

fn hash_text(message: &str, h: &mut impl Hasher) {
    for word in message.split_inclusive(|c: char| !c.is_alphanumeric()) {
        let (body, end) = match word.char_indices().last() {
            Some((i, c)) if !c.is_alphanumeric() => (&word[..i], Some(c)),
            _ => (word, None),
        };
        if body.chars().any(|c| c.is_ascii_digit()) {
            '#'.hash(h);
        } else {
            body.hash(h);
        }
        end.hash(h);
    }
}

/// The message of a line and the bytes it would take written.
struct Line {
    message: String,
    bytes: usize,
}

impl Visit for Line {
    fn record_debug(&mut self, field: &Field, value: &dyn std::fmt::Debug) {
        if field.name() == "message" {
            let _ = write!(self.message, "{value:?}");
            cut(&mut self.message, FIELD_LIMIT);
            self.bytes += self.message.len();
        } else {
            let mut text = String::new();
            let _ = write!(text, "{value:?}");
            self.bytes += field.name().len() + 2 + text.len().min(FIELD_LIMIT + '…'.len_utf8());
        }
    }
}

/// One kind's count in the current window.
struct Kind {
    written: u32,
    left_out: u64,
    level: Level,
    sample: String,
}

/// One window: every kind's count and the bytes written.
struct Window {
    start: Instant,
    kinds: HashMap<u64, Kind>,
    /// Call sites that wrote a line in this window.
    sites: std::collections::HashSet<u64>,
    bytes: usize,
    /// Lines left out only because the byte budget was spent, and their bytes.
    over_budget: (u64, u64),
}

impl Window {
    fn new(start: Instant) -> Self {
        Window { start, kinds: HashMap::new(), sites: Default::default(), bytes: 0, over_budget: (0, 0) }
    }

    /// The summary lines of what this window left out: the most frequent kinds one
    /// by one, the rest together, then the byte budget if it was reached.
    fn summaries(self) -> Vec<(Level, String)> {
        let secs = WINDOW.as_secs();
        let mut kinds: Vec<Kind> = self.kinds.into_values().filter(|k| k.left_out > 0).collect();
        kinds.sort_by(|a, b| b.left_out.cmp(&a.left_out).then(a.level.cmp(&b.level)));
        let worst = kinds.iter().map(|k| k.level).min();
        let rest = kinds.split_off(kinds.len().min(SUMMARIES));
        let mut out: Vec<(Level, String)> = kinds
            .into_iter()
            .map(|k| (k.level, format!("… {} more in the last {secs} s like: {}", k.left_out, k.sample)))
            .collect();
        if let Some(first) = rest.first() {
            let count: u64 = rest.iter().map(|k| k.left_out).sum();
            let level = rest.iter().map(|k| k.level).min().unwrap_or(first.level);
            out.push((
                level,
                format!("… {count} more in the last {secs} s of {} other kinds, e.g.: {}", rest.len(), first.sample),
            ));
        }
        let (lines, bytes) = self.over_budget;
        if lines > 0 {
            out.push((
                worst.unwrap_or(Level::WARN),
                format!(
                    "… the log's budget of {BUDGET} bytes per {secs} s was spent: {lines} of the lines counted above ({bytes} bytes) were left out for it"
                ),
            ));
        }
        out
    }
}

#[derive(Default)]
struct State {
    window: Option<Window>,
    /// Summaries of windows that are over, not yet written.
    due: Vec<(Level, String)>,
}

/// The rate limit: a `tracing` layer whose `event_enabled` drops a line past its
/// kind's burst or the window's byte budget.
#[derive(Default, Clone)]
struct RateLimit {
    state: std::sync::Arc<Mutex<State>>,
}

impl RateLimit {
    /// Whether a line of this call site, kind and size may be written at `now`;
    /// counts it if not.
    fn admit(
        &self,
        (site, kind): (u64, u64),
        level: Level,
        bytes: usize,
        message: impl FnOnce() -> String,
        now: Instant,
    ) -> bool {
        let mut state = self.state.lock().unwrap_or_else(|p| p.into_inner());
        let state = &mut *state;
        if state.window.as_ref().is_some_and(|w| now.duration_since(w.start) >= WINDOW)
            && let Some(over) = state.window.take()
        {
            state.due.extend(over.summaries());
        }
        let window = state.window.get_or_insert_with(|| Window::new(now));
        let full = window.kinds.len() >= MAX_KINDS && !window.kinds.contains_key(&kind);
        let k = window.kinds.entry(if full { 0 } else { kind }).or_insert_with(|| Kind {
            written: 0,
            left_out: 0,
            level,
            sample: String::new(),
        });
        if k.written < BURST {
            // Past the budget, a call site's first line in the window still goes:
            // there are as many as places in the code, whatever a peer sends.
            let first_of_site = window.sites.len() < MAX_KINDS && !window.sites.contains(&site);
            if window.bytes + bytes <= BUDGET || first_of_site {
                k.written += 1;
                window.bytes += bytes;
                window.sites.insert(site);
                return true;
            }
            window.over_budget.0 += 1;
            window.over_budget.1 += bytes as u64;
        }
        if k.left_out == 0 {
            k.sample = message();
        }
        k.left_out += 1;
        SUPPRESSED.fetch_add(1, Ordering::Relaxed);
        false
    }

    /// Writes the summaries of the windows over at `now` (with `all`, of the open
    /// one too).
    fn flush(&self, now: Instant, all: bool) {
        let due = {
            let mut state = self.state.lock().unwrap_or_else(|p| p.into_inner());
            if state.window.as_ref().is_some_and(|w| all || now.duration_since(w.start) >= WINDOW)
                && let Some(over) = state.window.take()
            {
                let summaries = over.summaries();
                state.due.extend(summaries);
            }
            std::mem::take(&mut state.due)
        };
        // Written after the lock is released, under the summaries' own target.
        for (level, text) in due {
            match level {
                Level::ERROR => tracing::error!(target: SUMMARY_TARGET, "{text}"),
                Level::WARN => tracing::warn!(target: SUMMARY_TARGET, "{text}"),
                _ => tracing::info!(target: SUMMARY_TARGET, "{text}"),
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
        if meta.target() == SUMMARY_TARGET {
            return true;
        }
        if level <= Level::WARN {
            WARNINGS.fetch_add(1, Ordering::Relaxed);
            if meta.target() == ICEORYX_TARGET {
                IPC_WARNINGS.fetch_add(1, Ordering::Relaxed);
            }
        }
        let mut line = Line { message: String::new(), bytes: LINE_OVERHEAD + meta.target().len() };
        event.record(&mut line);
        let kind = site_and_kind(event, &line.message);
        self.admit(kind, level, line.bytes, || line.message.clone(), Instant::now())
    }
}

/// The layer counting the lines of the tallies.
struct Tallies(&'static [&'static Tally]);

impl<S: Subscriber> Layer<S> for Tallies {
    fn event_enabled(&self, event: &Event<'_>, _ctx: Context<'_, S>) -> bool {
        let meta = event.metadata();
        let mut message: Option<String> = None;
        for tally in self.0.iter().filter(|t| t.covers(meta)) {
            let text = message.get_or_insert_with(|| {
                let mut line = Line { message: String::new(), bytes: 0 };
                event.record(&mut line);
                line.message
            });
            tally.count_line(text);
        }
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::sync::Arc;

    #[test]
    fn a_kind_is_written_burst_times_per_window_then_summarised() {
        let limit = RateLimit::default();
        let t0 = Instant::now();
        let admitted = (0..100).filter(|_| limit.admit((1, 1), Level::WARN, 100, || "flood".into(), t0)).count();
        assert_eq!(admitted, BURST as usize);
        // Another kind is not held back by the first.
        assert!(limit.admit((2, 2), Level::WARN, 100, || "other".into(), t0));
        let left_out = limit.state.lock().unwrap().window.as_ref().unwrap().kinds[&1].left_out;
        assert_eq!(left_out, 100 - u64::from(BURST));
        // Before the window is over nothing is summarised; after, the window goes.
        limit.flush(t0 + WINDOW / 2, false);
        assert!(limit.state.lock().unwrap().window.is_some());
        limit.flush(t0 + WINDOW, false);
        assert!(limit.state.lock().unwrap().window.is_none());
        // A new window writes again.
        assert!(limit.admit((1, 1), Level::WARN, 100, || "flood".into(), t0 + WINDOW));
    }

    #[test]
    fn lines_of_every_kind_together_stay_within_the_byte_budget() {
        let limit = RateLimit::default();
        let t0 = Instant::now();
        let line = 300;
        let mut written = 0;
        // One call site, 2000 texts.
        for kind in 0..2_000u64 {
            if limit.admit((7, kind), Level::WARN, line, || format!("kind {kind}"), t0) {
                written += line;
            }
        }
        assert!(written <= BUDGET && written + line > BUDGET, "{written} bytes written");
        let over = limit.state.lock().unwrap().window.as_ref().unwrap().over_budget;
        assert_eq!(over.0, 2_000 - (written / line) as u64, "every line past the budget is counted");
        // Another call site still says its first line, once.
        assert!(limit.admit((8, 1), Level::INFO, line, || "stopped".into(), t0));
        assert!(!limit.admit((8, 2), Level::INFO, line, || "stopped again".into(), t0));
        // The next window has a budget of its own; the summaries of the last one
        // are few, count every line left out and say why.
        assert!(limit.admit((7, 5), Level::WARN, line, || "again".into(), t0 + WINDOW));
        let due = std::mem::take(&mut limit.state.lock().unwrap().due);
        assert_eq!(due.len(), SUMMARIES + 2, "{due:#?}");
        assert_eq!(left_out_in(due.iter().map(|(_, s)| s.as_str())), over.0 + 1, "{due:#?}");
        assert!(due[SUMMARIES].1.contains(" other kinds, e.g.: "), "{:?}", due[SUMMARIES]);
        assert!(due[SUMMARIES + 1].1.contains("budget"), "{:?}", due[SUMMARIES + 1]);
    }

    /// The lines left out according to `summaries`.
    fn left_out_in<'a>(summaries: impl Iterator<Item = &'a str>) -> u64 {
        summaries.filter_map(|l| l.split("… ").nth(1)?.split(' ').next()?.parse::<u64>().ok()).sum()
    }

    #[test]
    fn words_with_digits_do_not_make_kinds() {
        let kind = |s: &str| {
            let mut h = std::collections::hash_map::DefaultHasher::new();
            hash_text(s, &mut h);
            h.finish()
        };
        assert_eq!(kind("peer 3fa9c01e refused at 12:04"), kind("peer 77b0 refused at 9:59"));
        assert_eq!(kind("bytes [12, 255, 0]"), kind("bytes [1, 2, 3]"));
        assert_ne!(kind("peer refused"), kind("peer accepted"));
        assert_ne!(kind("map v2 gone"), kind("map v2 kept"));
    }

    /// What the log writes, captured.
    #[derive(Clone, Default)]
    struct Captured(Arc<Mutex<Vec<u8>>>);

    impl std::io::Write for Captured {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.0.lock().unwrap().extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl Captured {
        fn text(&self) -> String {
            String::from_utf8_lossy(&self.0.lock().unwrap()).into_owned()
        }
    }

    /// The composition `init` installs, at `info`, writing into `out`.
    fn test_log(out: &Captured, tallies: &'static [&'static Tally]) -> (RateLimit, impl Subscriber + Send + Sync) {
        let limit = RateLimit::default();
        let out = out.clone();
        (limit.clone(), subscriber(EnvFilter::new("info"), limit, tallies, move || out.clone(), false))
    }

    /// A stranger's garbage quoted in every line (a new kind each time): the bytes
    /// written stay within the budget, and the summaries account for every line.
    #[test]
    fn garbage_quoted_in_every_line_is_bounded_in_bytes_and_counted() {
        let out = Captured::default();
        let (limit, subscriber) = test_log(&out, &[]);
        let lines = 5_000;
        tracing::subscriber::with_default(subscriber, || {
            let mut x = 1u64;
            for _ in 0..lines {
                // Letters only, so that every line is a kind of its own.
                let garbage: String = (0..150)
                    .map(|_| {
                        x = x.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                        (b'a' + (x >> 59) as u8 % 26) as char
                    })
                    .collect();
                tracing::error!(target: "zenoh_codec", "invalid frame from peer: {garbage} (field ({garbage}))");
            }
            // The process's own line, past the budget, from a call site of its own.
            tracing::info!(target: "dyfos_link", "link stopped");
            limit.flush(Instant::now(), true);
        });
        let text = out.text();
        let (summaries, written): (Vec<&str>, Vec<&str>) = text.lines().partition(|l| l.contains(SUMMARY_TARGET));
        assert!(written.last().is_some_and(|l| l.ends_with("link stopped")), "{written:#?}");
        let written_bytes: usize = written.iter().map(|l| l.len() + 1).sum();
        assert!(written_bytes <= BUDGET + 100, "{written_bytes} bytes of lines written");
        assert!(written.len() > 10, "only {} lines written", written.len());
        assert_eq!(summaries.len(), SUMMARIES + 2, "{summaries:#?}");
        let all = lines as u64 + 1;
        assert_eq!(left_out_in(summaries.iter().copied()), all - written.len() as u64, "{summaries:#?}");
        let summary_bytes: usize = summaries.iter().map(|l| l.len() + 1).sum();
        assert!(summary_bytes < (SUMMARIES + 2) * (FIELD_LIMIT + 150), "{summary_bytes} bytes of summaries");
    }

    /// A tally counts the lines of its kind below the log's level without writing
    /// them; lines of the same target not of its kind are neither counted nor written.
    #[test]
    fn a_tally_counts_lines_below_the_level_without_writing_them() {
        static DOS: Tally = Tally::new("zenoh_transport::unicast", Level::TRACE, "Closing link for preventing");
        static TALLIES: [&Tally; 1] = [&DOS];
        let out = Captured::default();
        let (_, subscriber) = test_log(&out, &TALLIES);
        tracing::subscriber::with_default(subscriber, || {
            for port in 0..30 {
                tracing::trace!(
                    target: "zenoh_transport::unicast::manager",
                    "Closing link for preventing potential DoS: tcp/10.0.0.9:{port}"
                );
                tracing::trace!(target: "zenoh_transport::unicast::manager", "Accepting link... {port}");
            }
            tracing::info!(target: "zenoh_transport::unicast::manager", "shown");
        });
        assert_eq!(DOS.count(), 30);
        assert_eq!(DOS.last(), "Closing link for preventing potential DoS: tcp/10.0.0.9:29");
        let text = out.text();
        assert_eq!(text.lines().count(), 1, "{text}");
        assert!(text.contains("shown"));
    }

    /// iceoryx2's own lines (its warning for each notification towards a dead
    /// client's listener) are counted and held back like ours.
    #[test]
    fn iceoryx2_warnings_are_counted_and_held_back() {
        use std::sync::atomic::AtomicUsize;
        struct Written(Arc<AtomicUsize>);
        impl<S: Subscriber> Layer<S> for Written {
            fn on_event(&self, _: &Event<'_>, _: Context<'_, S>) {
                self.0.fetch_add(1, Ordering::Relaxed);
            }
        }
        let written = Arc::new(AtomicUsize::new(0));
        let subscriber = tracing_subscriber::registry().with(RateLimit::default()).with(Written(Arc::clone(&written)));
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
