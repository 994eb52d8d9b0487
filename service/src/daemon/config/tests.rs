use super::former::FORMER_KEYS;
use super::*;
use std::path::Path;

fn load(sets: &[&str]) -> Result<DaemonConfig, String> {
    DaemonConfig::load(None, sets).map_err(|e| e.to_string())
}

/// A file of this test's own, removed when dropped.
struct File(PathBuf);

impl File {
    fn new(name: &str, text: &str) -> File {
        let path = std::env::temp_dir().join(format!("dyfosd-config-{}-{name}.toml", std::process::id()));
        std::fs::write(&path, text).unwrap();
        File(path)
    }
}

impl Drop for File {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

#[test]
fn the_defaults() {
    let d = DaemonConfig::default();
    assert_eq!((d.prefix.as_str(), d.domain.as_deref(), d.workers, d.model.as_deref()), ("dyfos/", None, 0, None));
    assert_eq!(d.state_dir, default_state_dir());
    assert_eq!(
        d.limits,
        Limits { max_clients: 64, max_requests_per_client: 4, max_queued: 256, upload_idle_timeout_s: 30 }
    );
    let s = &d.scheduling;
    assert_eq!((s.ipc_priority, s.poll(), s.poll_max()), (10, Duration::from_micros(200), Duration::from_millis(2)));
    assert_eq!((s.worker_yield(), s.worker_slice()), (Duration::from_micros(50), Duration::from_millis(3)));
    assert_eq!(s.cpu_latency_us.micros(), Some(0));
    assert_eq!((d.recording.path.as_deref(), d.recording.max_bytes, d.recording.keep), (None, 256 << 20, 4));
    assert_eq!(d.recording.record_config(), None);
    d.validate().unwrap();
    assert_eq!(load(&[]).unwrap(), d);
}

#[test]
fn sets_override_the_file_which_overrides_the_defaults() {
    let file = File::new(
        "precedence",
        "prefix = \"from-file/\"\nworkers = 3\n[limits]\nupload_idle_timeout_s = 9\n[scheduling]\npoll_us = 50\nipc_priority = 3\n",
    );
    let c =
        DaemonConfig::load(Some(&file.0), &["workers=5", "scheduling.poll_us=70", "scheduling.poll_us=80"]).unwrap();
    assert_eq!((c.prefix.as_str(), c.workers), ("from-file/", 5));
    assert_eq!((c.scheduling.poll_us, c.scheduling.ipc_priority), (80, 3), "the last --set wins");
    assert_eq!(c.limits.upload_idle_timeout(), Duration::from_secs(9));
    assert_eq!(c.limits.max_clients, 64, "a key the file leaves out keeps its default");
    assert_eq!(c.scheduling.poll_max_us, 2000);
    // Values are TOML; a bare word is a string.
    let c = load(&["prefix=lab/", "domain=\"lab_1\"", "recording.path=/tmp/t.mcap", "recording.keep=2"]).unwrap();
    assert_eq!((c.prefix.as_str(), c.domain.as_deref()), ("lab/", Some("lab_1")));
    let r = c.recording.record_config().unwrap();
    assert_eq!((r.path, r.keep, r.max_bytes), (PathBuf::from("/tmp/t.mcap"), 2, 256 << 20));
    assert_eq!(load(&["scheduling={ poll_us = 7 }"]).unwrap().scheduling.poll_us, 7);
    for (set, want) in [("off", None), ("\"off\"", None), ("20", Some(20))] {
        let c = load(&[&format!("scheduling.cpu_latency_us={set}")]).unwrap();
        assert_eq!(c.scheduling.cpu_latency_us.micros(), want, "{set}");
    }
}

#[test]
fn an_unknown_key_is_named_with_what_to_write() {
    for (sets, want) in [
        (&["prefx=a/"][..], ["--set prefx=a/: `prefx`", "did you mean `prefix`?"]),
        (&["limits.max_clientz=8"], ["`limits.max_clientz`", "did you mean `max_clients`?"]),
        (&["spin_us=5"], ["`spin_us`", "is now `scheduling.poll_us`"]),
        (&["worker_nice=5"], ["`worker_nice`", "was removed"]),
        (&["limits.max_queued=x"], ["--set limits.max_queued=x: `limits.max_queued`", "invalid type: string \"x\""]),
        (&["scheduling.cpu_latency_us=on"], ["`scheduling.cpu_latency_us`", "expected a number of µs or \"off\""]),
        (&["scheduling.poll_us=-1"], ["`scheduling.poll_us`", "-1"]),
        (&["prefix=a/", "prefix.x=1"], ["--set prefix.x=1: `prefix`", "is not a table"]),
        (&["workers"], ["--set `workers`", "KEY=VALUE"]),
        (&["Workers=2"], ["--set `Workers=2`", "KEY=VALUE"]),
    ] {
        let err = load(sets).unwrap_err();
        for w in want {
            assert!(err.contains(w), "{sets:?}: `{w}` not in: {err}");
        }
    }
    // A file of an earlier version (no tables) is told where each key went.
    let file = File::new("old", "prefix = \"a/\"\nmax_queued = 3\n");
    let err = DaemonConfig::load(Some(&file.0), &[] as &[&str]).unwrap_err().to_string();
    assert!(err.contains(&file.0.display().to_string()) && err.contains("is now `limits.max_queued`"), "{err}");
    let file = File::new("syntax", "prefix = \n");
    let err = DaemonConfig::load(Some(&file.0), &[] as &[&str]).unwrap_err().to_string();
    assert!(err.contains("not a TOML file") && err.contains("line 1"), "{err}");
    let err = DaemonConfig::load(Some(Path::new("/nonexistent/dyfosd.toml")), &[] as &[&str]).unwrap_err();
    assert!(err.to_string().contains("cannot read /nonexistent/dyfosd.toml"), "{err}");
}

#[test]
fn values_out_of_range_are_refused_with_the_range() {
    for (set, want) in [
        ("prefix=\"a b\"", "prefix = \"a b\" is refused: service prefix"),
        ("domain=\"a/b\"", "domain = \"a/b\" is refused"),
        ("limits.max_clients=0", "limits.max_clients = 0 must be at least 1"),
        ("limits.max_requests_per_client=0", "limits.max_requests_per_client = 0 must be at least 1"),
        ("limits.max_queued=0", "limits.max_queued = 0 must be at least 1"),
        ("scheduling.ipc_priority=100", "scheduling.ipc_priority = 100 must be 1–99"),
        ("scheduling.worker_yield_us=1000001", "scheduling.worker_yield_us = 1000001 must be at most 1000000"),
        ("scheduling.worker_slice_us=99", "scheduling.worker_slice_us = 99 must be 100–100000"),
        ("scheduling.worker_slice_us=100001", "scheduling.worker_slice_us = 100001 must be 100–100000"),
        ("scheduling.cpu_latency_us=1000001", "scheduling.cpu_latency_us = 1000001 must be at most 1000000"),
        ("recording.max_bytes=0", "recording.max_bytes = 0 must be at least 1"),
    ] {
        let err = load(&[set]).unwrap().validate().unwrap_err().to_string();
        assert!(err.contains(want), "{set}: {err}");
    }
    // The edges of each range are taken.
    let edges = [
        "scheduling.ipc_priority=0",
        "scheduling.ipc_priority=99",
        "scheduling.worker_yield_us=1000000",
        "scheduling.worker_slice_us=0",
        "scheduling.worker_slice_us=100",
        "scheduling.worker_slice_us=100000",
        "scheduling.cpu_latency_us=1000000",
        "recording.max_bytes=1",
        "limits.max_queued=1",
    ];
    for set in edges {
        load(&[set]).unwrap().validate().unwrap_or_else(|e| panic!("{set}: {e}"));
    }
    assert!(load(&["scheduling.ipc_priority=256"]).is_err(), "u8");
}

#[test]
fn a_former_flag_says_what_replaced_it() {
    let moved = former_flag("--spin-us").unwrap();
    assert!(
        moved.contains("--set scheduling.poll_us=VALUE") && moved.contains("`poll_us` under `[scheduling]`"),
        "{moved}"
    );
    assert!(former_flag("--record-keep=3").unwrap().contains("recording.keep"));
    assert!(former_flag("--queue").unwrap().contains("removed: the search queue is always fair"));
    assert!(former_flag("--legacy-scheduling").unwrap().contains("git worktree"));
    assert_eq!(former_flag("--prefx"), None);
    assert_eq!(former_flag("spin-us"), None);
}

/// The TOML printed and the JSON of a recording's head hold every key, and the
/// TOML reads back as the same configuration.
#[test]
fn printed_toml_reads_back_and_the_json_has_every_key() {
    let c = load(&["domain=d_1", "model=/m.bin", "recording.path=/r.mcap", "scheduling.cpu_latency_us=off"]).unwrap();
    let file = File::new("roundtrip", &c.to_toml());
    assert_eq!(DaemonConfig::load(Some(&file.0), &[] as &[&str]).unwrap(), c);
    let json = c.to_json(7);
    assert_eq!(json["workers"], 7, "workers as started");
    assert_eq!((json["prefix"].as_str(), json["model"].as_str()), (Some("dyfos/"), Some("/m.bin")));
    assert_eq!(json["scheduling"]["cpu_latency_us"], "off");
    assert_eq!(keys(&json), keys(&DaemonConfig::default().to_json(2)));
    assert!(DaemonConfig::default().to_json(2)["domain"].is_null());
}

/// Every key as a dotted path, in order.
fn keys(v: &serde_json::Value) -> Vec<String> {
    let mut out = Vec::new();
    for (k, v) in v.as_object().expect("an object") {
        match v.as_object() {
            Some(_) => out.extend(keys(v).into_iter().map(|sub| format!("{k}.{sub}"))),
            None => out.push(k.clone()),
        }
    }
    out
}

/// The key table of docs/daemon.md: key, default, meaning.
#[test]
fn the_documented_keys_and_defaults_are_the_structs() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("../docs/daemon.md");
    let doc = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let defaults = DaemonConfig::default().to_json(0);
    let want = keys(&defaults);
    let rows: Vec<Vec<&str>> = doc
        .lines()
        .skip_while(|l| !l.starts_with("| key |"))
        .skip(2)
        .take_while(|l| l.starts_with('|'))
        .map(|l| l.trim_matches('|').split(" | ").map(str::trim).collect())
        .collect();
    let documented: Vec<String> = rows.iter().map(|r| r[0].trim_matches('`').to_string()).collect();
    assert_eq!(documented, want, "docs/daemon.md's key table lists every key once, in the struct's order");
    for row in &rows {
        let key = row[0].trim_matches('`');
        let value = key.split('.').fold(&defaults, |v, k| &v[k]);
        let default = row[1];
        match default.strip_prefix('`').and_then(|d| d.strip_suffix('`')).filter(|d| !d.contains('`')) {
            // A literal default is the struct's, as TOML writes it.
            Some(literal) => {
                assert_eq!(literal, toml::Value::try_from(value).unwrap().to_string(), "default of {key}")
            }
            // Prose: a default that is unset or depends on the environment.
            None => assert!(value.is_null() || key == "state_dir", "{key}: write its default as `{value}`"),
        }
        assert!(row.len() == 3 && row[2].len() > 20, "{key} has a meaning");
    }
    // Every former flag or key is in the table of what replaced it.
    let former = doc.split("## Former flags").nth(1).expect("a section on former flags");
    for (key, _) in FORMER_KEYS {
        let (flag, key) = (format!("`--{}`", key.replace('_', "-")), format!("`{key}`"));
        assert!(former.contains(&flag) || former.contains(&key), "{key} is not among the former flags");
    }
}

/// The example file in the repository loads, sets every key it can to its
/// default, and names every other one.
#[test]
fn the_example_file_loads_and_shows_the_defaults() {
    let path = Path::new(env!("CARGO_MANIFEST_DIR")).join("dyfosd.example.toml");
    let example = DaemonConfig::load(Some(&path), &[] as &[&str]).unwrap();
    example.validate().unwrap();
    assert_eq!(example, DaemonConfig { state_dir: default_state_dir(), ..DaemonConfig::default() });
    let text = std::fs::read_to_string(&path).unwrap();
    for key in keys(&DaemonConfig::default().to_json(0)) {
        let name = key.rsplit('.').next().unwrap();
        assert!(
            text.lines().any(|l| l.trim_start_matches("# ").starts_with(&format!("{name} = "))),
            "{key} is not in the example"
        );
    }
}
