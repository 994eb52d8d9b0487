//! `docs/wire.md` is the wire protocol for clients written in other languages. These
//! tests read its tables and check every documented type name, size, alignment,
//! field offset and C type, every status, tag, flag, operation, mode, algorithm,
//! model and stop code, every parameter bit and SPEC default, and every limit
//! against the Rust definitions, in both directions: a documented entry Rust does
//! not have fails, and so does a Rust entry the document lacks. The services'
//! types and iceoryx2 limits are checked against a running `dyfosd`.
//!
//! The table format is described in the document's last section: a table is found
//! by the text of its first header cell, and a field table belongs to the `###`
//! heading above it. On a mismatch the tests print the rows they expected.

use dyfos_service::daemon::{CLIENT_CHECK, DaemonConfig, HOUSEKEEPING};
use dyfos_shared::answer::{Algorithm, StopReason};
use dyfos_shared::limits::{
    DETAIL_LEN, MAX_DEADLINE_MICROS, MAX_DELTAS_PER_MESSAGE, MAX_INLINE_DELTAS, MAX_MAPS, MAX_OBSTACLES,
    MAX_OCCUPIED_VOXELS, MAX_PENDING_UPLOADS, MAX_PERIMETER_POINTS, MAX_PREFIX_LEN, MAX_UPLOAD_CHUNKS,
};
use dyfos_shared::params::{ModelKind, Params};
use dyfos_shared::prelude::na;
use dyfos_shared::wire::map::{
    FLAG_REPLACE, MapReplyHeader, MapRequest, MapRequestHeader, WireDelta, decode_deltas, encode_deltas, op, tag,
};
use dyfos_shared::wire::rendezvous::{Mode, RendezvousReply, RendezvousRequest, RendezvousRequestHeader, WireParams};
use dyfos_shared::wire::stats::{STATUS_SLOTS, StatsReply, StatsRequest};
use dyfos_shared::wire::{ANY_VERSION, DEFAULT_PREFIX, Detail, ServiceNames, Status};
use dyfos_shared::world::{AxisBox, Bounds, MapDelta, Obstacle, Sun, VerticalCylinder};
use dyfos_tests::Sandbox;
use iceoryx2::service::static_config::message_type_details::{TypeDetail, TypeVariant};
use std::collections::BTreeMap;

const DOC: &str = include_str!("../../../docs/wire.md");

/// One Markdown table of the document.
#[derive(Debug)]
struct Table {
    /// The nearest `#`…`###` heading above it, without the `#`s.
    heading: String,
    /// Header cells.
    header: Vec<String>,
    /// Body rows, cells trimmed.
    rows: Vec<Vec<String>>,
    /// 1-based line of its header, for messages.
    line: usize,
}

/// Every table of `doc` outside code fences.
fn tables(doc: &str) -> Vec<Table> {
    let mut out = Vec::new();
    let mut heading = String::new();
    let mut fenced = false;
    let mut current: Option<Table> = None;
    for (i, raw) in doc.lines().enumerate() {
        let line = raw.trim();
        if line.starts_with("```") {
            fenced = !fenced;
        }
        if !fenced && line.starts_with('|') {
            let cells = cells(line);
            match &mut current {
                None => {
                    current = Some(Table { heading: heading.clone(), header: cells, rows: Vec::new(), line: i + 1 })
                }
                Some(t) if cells.iter().all(|c| c.chars().all(|ch| matches!(ch, '-' | ':'))) && t.rows.is_empty() => {}
                Some(t) => {
                    assert_eq!(
                        cells.len(),
                        t.header.len(),
                        "docs/wire.md line {}: {} cells, the table's header has {}",
                        i + 1,
                        cells.len(),
                        t.header.len()
                    );
                    t.rows.push(cells);
                }
            }
            continue;
        }
        out.extend(current.take());
        if !fenced && line.starts_with('#') {
            heading = line.trim_start_matches('#').trim().to_string();
        }
    }
    out.extend(current.take());
    out
}

/// The cells of a table row: split at every `|` that is not written `\\|`.
fn cells(line: &str) -> Vec<String> {
    let inner = line.strip_prefix('|').unwrap_or(line);
    let inner = inner.strip_suffix('|').unwrap_or(inner);
    let mut out = vec![String::new()];
    let mut chars = inner.chars().peekable();
    while let Some(c) = chars.next() {
        match c {
            '\\' if chars.peek() == Some(&'|') => {
                out.last_mut().expect("a cell").push('|');
                chars.next();
            }
            '|' => out.push(String::new()),
            c => out.last_mut().expect("a cell").push(c),
        }
    }
    out.into_iter().map(|c| c.trim().to_string()).collect()
}

/// The tables whose first header cell is `first`.
fn tables_of<'a>(all: &'a [Table], first: &str) -> Vec<&'a Table> {
    all.iter().filter(|t| t.header[0] == first).collect()
}

/// The one table whose first header cell is `first`.
fn table<'a>(all: &'a [Table], first: &str) -> &'a Table {
    let found = tables_of(all, first);
    assert_eq!(found.len(), 1, "docs/wire.md must have exactly one table whose first column is `{first}`");
    found[0]
}

/// The text of the first `code` span of `cell`, or the cell itself.
fn code(cell: &str) -> &str {
    let mut parts = cell.split('`');
    match (parts.next(), parts.next()) {
        (Some(_), Some(inner)) => inner,
        _ => cell.trim(),
    }
}

/// The integer at the start of `cell` (decimal, or hex with `0x`; `_` ignored).
fn int(cell: &str) -> u64 {
    let token: String = code(cell).split_whitespace().next().unwrap_or("").replace('_', "");
    let parsed = match token.strip_prefix("0x") {
        Some(hex) => u64::from_str_radix(hex, 16),
        None => token.parse(),
    };
    parsed.unwrap_or_else(|_| panic!("docs/wire.md: `{cell}` does not start with an integer"))
}

/// Compares documented rows with expected ones (as strings), printing both on a
/// mismatch so the document is easy to fix.
fn same_rows(what: &str, table: &Table, documented: Vec<String>, expected: Vec<String>) {
    assert!(
        documented == expected,
        "docs/wire.md line {} ({what}) differs from the Rust definitions.\n  documented:\n    {}\n  expected:\n    {}",
        table.line,
        documented.join("\n    "),
        expected.join("\n    ")
    );
}

// ----- types and fields ---------------------------------------------------------

/// One field of a wire type, from Rust.
struct Field {
    name: &'static str,
    offset: usize,
    rust_type: &'static str,
}

/// One wire type, from Rust and iceoryx2.
struct WireType {
    type_name: String,
    size: usize,
    align: usize,
    fields: Vec<Field>,
}

/// The field names `Debug` prints for `value` (every field, in declaration order):
/// so a field added to a wire type and not to [`wire_types`] fails the test.
fn debug_fields(value: &impl std::fmt::Debug) -> Vec<String> {
    format!("{value:#?}")
        .lines()
        .filter_map(|l| l.strip_prefix("    "))
        .filter(|l| !l.starts_with(' '))
        .filter_map(|l| l.split_once(':').map(|(name, _)| name.to_string()))
        .collect()
}

macro_rules! wire_type {
    ($t:ty { $($f:ident),* $(,)? }) => {{
        let value = <$t>::default();
        // What iceoryx2 itself compares when a port opens the service.
        let detail = TypeDetail::new::<$t>(TypeVariant::FixedSize);
        let fields = vec![$(Field {
            name: stringify!($f),
            offset: std::mem::offset_of!($t, $f),
            rust_type: std::any::type_name_of_val(&value.$f),
        }),*];
        let listed: Vec<String> = fields.iter().map(|f| f.name.to_string()).collect();
        assert_eq!(listed, debug_fields(&value), "this test's field list of {} is out of date", stringify!($t));
        assert_eq!((detail.size(), detail.alignment()), (size_of::<$t>(), align_of::<$t>()));
        WireType { type_name: detail.type_name().to_string(), size: detail.size(), align: detail.alignment(), fields }
    }};
}

/// Every payload and header type of the daemon's services.
fn wire_types() -> Vec<WireType> {
    vec![
        wire_type!(RendezvousRequestHeader {
            request_id,
            map_id,
            expected_version,
            seed,
            budget,
            deadline_micros,
            mean,
            cov,
            params,
            algorithm,
            mode,
            reply_to
        }),
        wire_type!(WireParams {
            rover_radius,
            marker_size,
            marker_height,
            viewer_radius,
            safety_margin,
            z_min,
            z_max,
            camera_pitch,
            t_vs,
            f_h,
            f_v,
            rho_min,
            rho_max,
            kappa,
            lambda,
            perimeter_points,
            model,
            set,
            reserved
        }),
        wire_type!(RendezvousReply {
            status,
            algorithm,
            stop,
            mode,
            request_id,
            map_version,
            x,
            cost,
            sensor_position,
            sensor_quaternion,
            viewer_position,
            viewer_yaw,
            r,
            posterior,
            evaluations,
            micros,
            daemon_micros,
            error_index,
            detail
        }),
        wire_type!(WireDelta { tag, flag, id, reserved, values, cell }),
        wire_type!(MapRequestHeader {
            op,
            flags,
            map_id,
            expected_version,
            request_id,
            upload_id,
            chunk_index,
            chunk_count,
            bounds,
            sun,
            reply_to
        }),
        wire_type!(MapReplyHeader {
            status,
            chunk_index,
            chunk_count,
            generation,
            request_id,
            map_id,
            version,
            bounds,
            sun,
            error_index,
            detail
        }),
        wire_type!(StatsRequest { request_id, reply_to }),
        wire_type!(StatsReply {
            request_id,
            pid,
            uptime_micros,
            queries_served,
            requests_failed,
            map_requests,
            maps,
            queued,
            running,
            workers,
            latency_micros,
            latency_samples,
            errors_by_code,
            queries_abandoned,
            receive_failures,
            log_warnings,
            ipc_warnings,
            log_suppressed
        }),
        wire_type!(Detail { len, bytes }),
    ]
}

/// The Rust type a documented C type stands for, as [`short_rust_type`] prints it:
/// `double[3][3]` is `[[f64; 3]; 3]`, a struct is its name.
fn rust_type_of_c(c: &str) -> String {
    let base_end = c.find('[').unwrap_or(c.len());
    let mut t = match &c[..base_end] {
        "uint8_t" => "u8",
        "uint32_t" => "u32",
        "int64_t" => "i64",
        "uint64_t" => "u64",
        "double" => "f64",
        other => other,
    }
    .to_string();
    let dims: Vec<&str> = c[base_end..].split(['[', ']']).filter(|s| !s.is_empty()).collect();
    for d in dims.iter().rev() {
        t = format!("[{t}; {d}]");
    }
    t
}

/// A Rust type name with every path shortened to its last segment
/// (`[dyfos_shared::wire::Detail; 2]` is `[Detail; 2]`).
fn short_rust_type(t: &str) -> String {
    let mut out = String::new();
    let mut word = String::new();
    for c in t.chars().chain(std::iter::once(' ')) {
        if c.is_alphanumeric() || c == '_' || c == ':' {
            word.push(c);
        } else {
            out.push_str(word.rsplit("::").next().unwrap_or(""));
            word.clear();
            out.push(c);
        }
    }
    out.pop();
    out
}

#[test]
fn documented_types_sizes_and_fields_are_the_rust_ones() {
    let all = tables(DOC);
    let types = wire_types();
    let summary = table(&all, "type name");
    let documented: Vec<String> =
        summary.rows.iter().map(|r| format!("| `{}` | {} | {} |", code(&r[0]), int(&r[1]), int(&r[2]))).collect();
    let expected: Vec<String> =
        types.iter().map(|t| format!("| `{}` | {} | {} |", t.type_name, t.size, t.align)).collect();
    same_rows("type name, size, align", summary, documented, expected);

    let field_tables = tables_of(&all, "offset");
    let documented_types: Vec<String> = field_tables.iter().map(|t| code(&t.heading).to_string()).collect();
    let expected_types: Vec<String> = types.iter().map(|t| t.type_name.clone()).collect();
    assert_eq!(documented_types, expected_types, "docs/wire.md: one field table per type, under `### `type name``");
    for (t, doc) in types.iter().zip(field_tables) {
        assert_eq!(&doc.header[..3], ["offset", "field", "C type"], "docs/wire.md line {}", doc.line);
        let documented: Vec<String> = doc
            .rows
            .iter()
            .map(|r| format!("| {} | `{}` | `{}` |", int(&r[0]), code(&r[1]), rust_type_of_c(code(&r[2]))))
            .collect();
        let expected: Vec<String> = t
            .fields
            .iter()
            .map(|f| format!("| {} | `{}` | `{}` |", f.offset, f.name, short_rust_type(f.rust_type)))
            .collect();
        same_rows(&format!("fields of {}", t.type_name), doc, documented, expected);
    }
}

// ----- codes ----------------------------------------------------------------------

/// Documented `(number, name)` pairs of the table whose first column is `first`.
fn codes<'a>(all: &'a [Table], first: &str) -> (&'a Table, Vec<(u64, String)>) {
    let t = table(all, first);
    (t, t.rows.iter().map(|r| (int(&r[0]), code(&r[1]).to_string())).collect())
}

fn rows(pairs: &[(u64, String)]) -> Vec<String> {
    pairs.iter().map(|(n, name)| format!("| {n} | `{name}` |")).collect()
}

/// Checks that the code table whose first column is `first` lists `expected`, as
/// `what`; returns the documented (code, name) rows.
fn same_codes(all: &[Table], first: &str, what: &str, expected: &[(u64, String)]) -> Vec<(u64, String)> {
    let (t, documented) = codes(all, first);
    same_rows(what, t, rows(&documented), rows(expected));
    documented
}

/// The (code, name) of every code 0..=256 that `decode` accepts.
fn decoded_codes(decode: impl Fn(u32) -> Option<String>) -> Vec<(u64, String)> {
    (0..=256u32).filter_map(|c| decode(c).map(|name| (u64::from(c), name))).collect()
}

/// A valid rendezvous request header, to vary one field of.
fn valid_rendezvous_header() -> RendezvousRequestHeader {
    let belief =
        dyfos_shared::posterior::Belief::new([0.0, 0.0, 0.3], [[0.2, 0.05, 0.0], [0.05, 0.1, 0.0], [0.0, 0.0, 0.05]])
            .expect("belief");
    RendezvousRequest::new(1, belief).header(Mode::Solve, 1, [0, 0])
}

#[test]
fn documented_status_codes_are_the_rust_ones() {
    let all = tables(DOC);
    let t = table(&all, "status");
    assert_eq!(&t.header[..3], ["status", "name", "retryable"]);
    let yes_no = |b: bool| if b { "yes" } else { "no" };
    let documented = t
        .rows
        .iter()
        .map(|r| format!("| {} | `{}` | {} |", int(&r[0]), code(&r[1]), r[2].split_whitespace().next().unwrap_or("")))
        .collect();
    let expected = Status::ALL
        .iter()
        .map(|s| format!("| {} | `{}` | {} |", *s as u32, s.name(), yes_no(s.is_retryable())))
        .collect();
    same_rows("status codes", t, documented, expected);
}

/// The tag constant name of the first record of `delta`: exhaustive, so a new kind
/// of delta fails to compile here until it is documented.
fn tag_name(delta: &MapDelta) -> &'static str {
    match delta {
        MapDelta::UpsertObstacle { obstacle: Obstacle::Cylinder(_), .. } => "UPSERT_CYLINDER",
        MapDelta::UpsertObstacle { obstacle: Obstacle::Box(_), .. } => "UPSERT_BOX",
        MapDelta::RemoveObstacle { .. } => "REMOVE_OBSTACLE",
        MapDelta::SetVoxels { .. } => "VOXEL_RUN",
        MapDelta::SetVoxelBlocks { .. } => "VOXEL_BLOCK_RUN",
        MapDelta::SetSun(_) => "SET_SUN",
        MapDelta::SetBounds(_) => "SET_BOUNDS",
        MapDelta::Clear => "CLEAR",
    }
}

#[test]
fn documented_delta_tags_and_flags_are_the_rust_ones() {
    let all = tables(DOC);
    let expected: Vec<(u64, String)> = tag::ALL.iter().map(|(n, s)| (u64::from(*n), s.to_string())).collect();
    let documented = same_codes(&all, "tag", "delta tags", &expected);
    // The range the text states, and the one an unknown tag's error message gives.
    let (first, last) = (tag::ALL[0].0, tag::ALL[tag::ALL.len() - 1].0);
    assert!(DOC.contains(&format!("Tags are {first} ..= {last}; any other is `malformed_delta`")), "docs/wire.md §4.2");
    let refused = decode_deltas(&[WireDelta { tag: last + 1, ..WireDelta::default() }]).unwrap_err();
    assert!(refused.message.contains(&format!("{last} (VOXEL_BLOCK)")), "{refused}");
    let by_name: BTreeMap<&str, u32> = documented.iter().map(|(n, s)| (s.as_str(), *n as u32)).collect();

    // Every kind of delta encodes with its documented tag (a voxel run's cells too).
    let cylinder = VerticalCylinder { center: na::Point2::new(1.0, 2.0), radius: 0.5, height: 2.0 };
    let crate_ = AxisBox { min: na::Point3::new(0.0, 0.0, 0.0), max: na::Point3::new(1.0, 1.0, 1.0) };
    let every_kind = [
        MapDelta::UpsertObstacle { id: 1, obstacle: Obstacle::Cylinder(cylinder) },
        MapDelta::UpsertObstacle { id: 2, obstacle: Obstacle::Box(crate_) },
        MapDelta::RemoveObstacle { id: 1 },
        MapDelta::SetVoxels { resolution: 0.5, origin: na::Point3::origin(), cells: vec![[1, 2, 3]], occupied: true },
        MapDelta::SetVoxelBlocks {
            resolution: 0.5,
            origin: na::Point3::origin(),
            blocks: vec![dyfos_shared::world::VoxelBlock { min: [4, -8, 0], mask: 1 << 63 | 5 }],
            occupied: true,
        },
        MapDelta::SetSun(Sun::new(0.3, 1.0).expect("sun")),
        MapDelta::SetBounds(Bounds::new([-5.0, -5.0, 5.0, 5.0]).expect("bounds")),
        MapDelta::Clear,
    ];
    for delta in &every_kind {
        let records = encode_deltas(std::slice::from_ref(delta));
        assert_eq!(records[0].tag, by_name[tag_name(delta)], "{delta:?}");
        for item in &records[1..] {
            let expected = if records[0].tag == by_name["VOXEL_RUN"] { "VOXEL_CELL" } else { "VOXEL_BLOCK" };
            assert_eq!(item.tag, by_name[expected], "{delta:?}");
        }
        // The documented mask layout: high half in `flag`, low half in `id`.
        if let MapDelta::SetVoxelBlocks { blocks, .. } = delta {
            assert_eq!((records[1].flag, records[1].id, records[1].cell), (1 << 31, 5, blocks[0].min));
        }
    }
    // A record with an undocumented tag is refused; a documented one is a delta (a
    // cell only inside a run).
    for t in 0..=256u32 {
        let result = decode_deltas(&[WireDelta { tag: t, ..WireDelta::default() }]);
        let known = by_name.values().any(|v| *v == t);
        match result {
            Ok(_) => assert!(known, "tag {t} decodes but is not documented"),
            Err(e) if e.message.contains("outside a run") => assert_eq!(t, by_name["VOXEL_CELL"]),
            Err(e) if e.message.contains("outside a block run") => assert_eq!(t, by_name["VOXEL_BLOCK"]),
            Err(e) => assert!(!known && e.message.contains("is not a delta"), "tag {t}: {e}"),
        }
    }

    // Flags: the upload's replace bit and a voxel run's occupied/free.
    let f = table(&all, "flag");
    let documented: Vec<String> =
        f.rows.iter().map(|r| format!("| {} | `{}` | `{}` |", int(&r[0]), code(&r[1]), code(&r[2]))).collect();
    let run = |occupied| {
        encode_deltas(&[MapDelta::SetVoxels { resolution: 1.0, origin: na::Point3::origin(), cells: vec![], occupied }])
            [0]
        .flag
    };
    let expected = vec![
        format!("| {FLAG_REPLACE} | `FLAG_REPLACE` | `MapRequestHeader.flags` |"),
        format!("| {} | `free` | `WireDelta.flag` |", run(false)),
        format!("| {} | `occupied` | `WireDelta.flag` |", run(true)),
    ];
    same_rows("flags", f, documented, expected);
    let upload = MapRequest::Upload {
        map: 1,
        upload_id: 1,
        chunk_index: 0,
        chunk_count: 1,
        replace: false,
        expected_version: None,
        bounds: Bounds::new([-5.0, -5.0, 5.0, 5.0]).expect("bounds"),
        sun: Sun::new(0.3, 1.0).expect("sun"),
        deltas: vec![],
    }
    .header(1, [0, 0]);
    for bit in 0..32 {
        let accepted = MapRequest::decode(&MapRequestHeader { flags: 1 << bit, ..upload }, &[]).is_ok();
        assert_eq!(accepted, 1 << bit == FLAG_REPLACE, "upload flag bit {bit}");
    }
    for flag in 0..=16 {
        let mut records = encode_deltas(&[MapDelta::SetVoxels {
            resolution: 1.0,
            origin: na::Point3::origin(),
            cells: vec![],
            occupied: false,
        }]);
        records[0].flag = flag;
        assert_eq!(decode_deltas(&records).is_ok(), flag == run(false) || flag == run(true), "voxel run flag {flag}");
    }
}

#[test]
fn documented_operations_modes_algorithms_models_and_stops_are_the_rust_ones() {
    let all = tables(DOC);

    let expected: Vec<(u64, String)> = op::ALL.iter().map(|(n, s)| (u64::from(*n), s.to_string())).collect();
    let documented = same_codes(&all, "op", "map operations", &expected);
    for o in 0..=256u32 {
        let refused = MapRequest::decode(&MapRequestHeader { op: o, ..MapRequestHeader::default() }, &[])
            .is_err_and(|e| e.message.contains("is not a map operation"));
        assert_eq!(refused, !documented.iter().any(|(n, _)| *n == u64::from(o)), "op {o}");
    }

    let decoded = decoded_codes(|m| {
        let (_, mode) =
            RendezvousRequest::decode(&RendezvousRequestHeader { mode: m, ..valid_rendezvous_header() }, &[]).ok()?;
        let name = match mode {
            Mode::Solve => "solve",
            Mode::Check => "check",
        };
        Some(name.to_string())
    });
    same_codes(&all, "mode", "modes", &decoded);

    let decoded = decoded_codes(|a| {
        let header = RendezvousRequestHeader { algorithm: a, ..valid_rendezvous_header() };
        RendezvousRequest::decode(&header, &[]).ok().map(|(request, _)| request.algorithm.name().to_string())
    });
    let from_all: Vec<(u64, String)> =
        Algorithm::ALL.iter().enumerate().map(|(i, a)| (i as u64, a.name().to_string())).collect();
    assert_eq!(decoded, from_all);
    same_codes(&all, "algorithm", "algorithms", &decoded);

    let decoded = decoded_codes(|m| {
        let wire = WireParams { model: m, set: WireParams::bit("model").expect("model bit"), ..WireParams::default() };
        Params::try_from(&wire).ok().map(|p| p.model.name().to_string())
    });
    assert_eq!(decoded.len(), [ModelKind::Paper, ModelKind::Anisotropic, ModelKind::Learned].len());
    same_codes(&all, "model", "models", &decoded);

    let decoded = decoded_codes(|s| {
        let answer = RendezvousReply { stop: s, ..RendezvousReply::checked(1, 0) }.decode_answer().ok()?;
        let name = serde_json::to_value(answer.stop).expect("stop as JSON");
        Some(name.as_str().expect("a name").to_string())
    });
    let _every_stop_is_known = |s: StopReason| match s {
        StopReason::Finished
        | StopReason::MaxGenerations
        | StopReason::Budget
        | StopReason::Deadline
        | StopReason::Abandoned => (),
    };
    same_codes(&all, "stop", "stop reasons", &decoded);
}

/// The wire value of parameter `name` in `w` as numbers (`t_vs` as its three), for
/// every parameter of the one list in `dyfos_shared::params` (a parameter the
/// document lacks fails the table check below).
fn param_values(w: &WireParams, name: &str) -> Vec<f64> {
    /// A wire field's numbers.
    trait Numbers {
        fn numbers(&self) -> Vec<f64>;
    }
    impl Numbers for f64 {
        fn numbers(&self) -> Vec<f64> {
            vec![*self]
        }
    }
    impl Numbers for u32 {
        fn numbers(&self) -> Vec<f64> {
            vec![f64::from(*self)]
        }
    }
    impl Numbers for [f64; 3] {
        fn numbers(&self) -> Vec<f64> {
            self.to_vec()
        }
    }
    macro_rules! values {
        ($($(#[doc = $doc:literal])* #[wire($slot:literal)] $name:ident: $ty:ty = $default:expr,)*) => {
            match name {
                $(stringify!($name) => w.$name.numbers(),)*
                other => panic!("no parameter `{other}`"),
            }
        };
    }
    dyfos_shared::spec_params!(values)
}

#[test]
fn documented_parameter_bits_and_defaults_are_the_rust_ones() {
    let all = tables(DOC);
    let t = table(&all, "bit");
    assert_eq!(&t.header[..4], ["bit", "mask", "parameter", "default"]);
    let defaults = WireParams::from(&Params::default());
    // Exact numbers: Rust's shortest round-trip form, so the text is the f64 bit for bit.
    let show = |v: &[f64]| {
        let parts: Vec<String> = v.iter().map(|x| format!("{x:?}")).collect();
        if parts.len() == 1 { parts[0].clone() } else { format!("[{}]", parts.join(", ")) }
    };
    let documented: Vec<String> = t
        .rows
        .iter()
        .map(|r| {
            let numbers: Vec<f64> = code(&r[3])
                .trim_matches(['[', ']'])
                .split(',')
                .map(|x| {
                    x.trim().parse().unwrap_or_else(|_| panic!("docs/wire.md line {}: default `{}`", t.line, r[3]))
                })
                .collect();
            format!("| {} | {:#x} | `{}` | `{}` |", int(&r[0]), int(&r[1]), code(&r[2]), show(&numbers))
        })
        .collect();
    let expected: Vec<String> = WireParams::FIELDS
        .iter()
        .enumerate()
        .map(|(i, name)| {
            let mask = WireParams::bit(name).expect("bit");
            assert_eq!(mask, 1 << i);
            format!("| {i} | {mask:#x} | `{name}` | `{}` |", show(&param_values(&defaults, name)))
        })
        .collect();
    same_rows("parameter bits and defaults", t, documented, expected);
    // The SPEC defaults are what a request with no bit set gets.
    assert_eq!(Params::try_from(&WireParams::default()).expect("all defaults"), Params::default());
}

#[test]
fn documented_constants_are_the_rust_ones() {
    let all = tables(DOC);
    let t = table(&all, "constant");
    let config = DaemonConfig::default();
    let expected: Vec<(&str, String)> = vec![
        ("ANY_VERSION", ANY_VERSION.to_string()),
        ("DEFAULT_PREFIX", DEFAULT_PREFIX.to_string()),
        ("MAX_PREFIX_LEN", MAX_PREFIX_LEN.to_string()),
        ("DETAIL_LEN", DETAIL_LEN.to_string()),
        ("STATUS_SLOTS", STATUS_SLOTS.to_string()),
        ("WireParams::ALL_SET", WireParams::ALL_SET.to_string()),
        ("MAX_INLINE_DELTAS", MAX_INLINE_DELTAS.to_string()),
        ("MAX_DELTAS_PER_MESSAGE", MAX_DELTAS_PER_MESSAGE.to_string()),
        ("SNAPSHOT_PAGE_RECORDS", dyfos_shared::limits::SNAPSHOT_PAGE_RECORDS.to_string()),
        ("MAX_UPLOAD_CHUNKS", MAX_UPLOAD_CHUNKS.to_string()),
        ("MAX_PENDING_UPLOADS", MAX_PENDING_UPLOADS.to_string()),
        ("MAX_MAPS", MAX_MAPS.to_string()),
        ("MAX_OBSTACLES", MAX_OBSTACLES.to_string()),
        ("MAX_OCCUPIED_VOXELS", MAX_OCCUPIED_VOXELS.to_string()),
        ("MAX_TOTAL_VOXELS", dyfos_shared::limits::MAX_TOTAL_VOXELS.to_string()),
        ("MAX_VOXEL_BLOCKS_SPANNED", dyfos_shared::limits::MAX_VOXEL_BLOCKS_SPANNED.to_string()),
        ("MAX_PERIMETER_POINTS", MAX_PERIMETER_POINTS.to_string()),
        ("MAX_DEADLINE_MICROS", MAX_DEADLINE_MICROS.to_string()),
        ("MAX_COORDINATE", dyfos_shared::limits::MAX_COORDINATE.to_string()),
        ("MAX_VOXEL_INDEX", dyfos_shared::limits::MAX_VOXEL_INDEX.to_string()),
        ("max_clients", config.limits.max_clients.to_string()),
        ("max_requests_per_client", config.limits.max_requests_per_client.to_string()),
        ("max_queued", config.limits.max_queued.to_string()),
        ("upload_idle_timeout_s", config.limits.upload_idle_timeout_s.to_string()),
        ("housekeeping_s", HOUSEKEEPING.as_secs().to_string()),
        ("client_check_ms", CLIENT_CHECK.as_millis().to_string()),
    ];
    let documented: Vec<String> = t
        .rows
        .iter()
        .map(|r| {
            let value = code(&r[1]).replace('_', "");
            let value = match value.strip_prefix("0x") {
                Some(hex) => u64::from_str_radix(hex, 16).map_or(value.clone(), |v| v.to_string()),
                None => value.clone(),
            };
            format!("| `{}` | `{value}` |", code(&r[0]))
        })
        .collect();
    let expected = expected.iter().map(|(n, v)| format!("| `{n}` | `{}` |", v.replace('_', ""))).collect();
    same_rows("constants", t, documented, expected);
}

// ----- the running daemon's services -------------------------------------------

/// How a documented payload or header cell reads in iceoryx2's type details.
fn type_cell(detail: &TypeDetail) -> String {
    match detail.variant() {
        TypeVariant::Dynamic => format!("`[{}]`", detail.type_name()),
        TypeVariant::FixedSize => format!("`{}`", detail.type_name()),
    }
}

#[test]
fn documented_services_and_limits_are_what_dyfosd_creates() {
    use iceoryx2::prelude::*;
    use iceoryx2::service::static_config::messaging_pattern::MessagingPattern;

    let all = tables(DOC);
    let (sandbox, _daemon) = Sandbox::with_daemon("wire-doc");
    let mut config = iceoryx2::config::Config::default();
    config.global.prefix = FileName::new(sandbox.domain.as_bytes()).expect("domain");
    let mut services = BTreeMap::new();
    ipc::Service::list(&config, |s| {
        services.insert(s.static_details.name().to_string(), s.static_details);
        CallbackProgression::Continue
    })
    .expect("list the domain's services");

    let sizes: BTreeMap<String, (u64, u64)> =
        table(&all, "type name").rows.iter().map(|r| (code(&r[0]).to_string(), (int(&r[1]), int(&r[2])))).collect();
    let t = table(&all, "service");
    assert_eq!(
        &t.header,
        &["service", "pattern", "request payload", "request header", "response payload", "response header"]
    );
    let names = ServiceNames::new(&sandbox.prefix).expect("prefix");
    let documented: Vec<String> = t
        .rows
        .iter()
        .map(|r| r.iter().map(|c| c.replace("<prefix>", &sandbox.prefix)).collect::<Vec<_>>().join(" | "))
        .collect();
    let mut expected = Vec::new();
    let mut rr_settings = Vec::new();
    let mut event_settings = Vec::new();
    for name in [&names.rendezvous, &names.map, &names.stats, &names.wake, &names.reply] {
        let s = services.remove(name.as_str()).unwrap_or_else(|| panic!("dyfosd did not create `{name}`"));
        let row = match s.messaging_pattern() {
            MessagingPattern::RequestResponse(rr) => {
                let (req, resp) = (rr.request_message_type_details(), rr.response_message_type_details());
                for d in [&req.user_header, &req.payload, &resp.user_header, &resp.payload] {
                    let n = d.type_name().to_string();
                    let want = sizes.get(&n).copied().unwrap_or((0, 1));
                    assert_eq!((d.size() as u64, d.alignment() as u64), want, "size and alignment of `{n}`");
                }
                rr_settings.push(vec![
                    format!("max_servers {}", rr.max_servers()),
                    format!("max_clients {}", rr.max_clients()),
                    format!("max_nodes {}", rr.max_nodes()),
                    format!("max_active_requests_per_client {}", rr.max_active_requests_per_client()),
                    format!("max_response_buffer_size {}", rr.max_response_buffer_size()),
                    format!("max_loaned_requests {}", rr.max_loaned_requests()),
                    format!(
                        "max_borrowed_responses_per_pending_response {}",
                        rr.max_borrowed_responses_per_pending_response()
                    ),
                    format!("fire_and_forget_requests {}", rr.does_support_fire_and_forget_requests()),
                    format!("enable_safe_overflow_for_requests {}", rr.has_safe_overflow_for_requests()),
                    format!("enable_safe_overflow_for_responses {}", rr.has_safe_overflow_for_responses()),
                ]);
                [
                    format!("`{name}`"),
                    "request-response".to_string(),
                    type_cell(&req.payload),
                    type_cell(&req.user_header),
                    type_cell(&resp.payload),
                    type_cell(&resp.user_header),
                ]
            }
            MessagingPattern::Event(e) => {
                let or_none = |v: Option<String>| v.unwrap_or_else(|| "none".to_string());
                event_settings.push(vec![
                    format!("max_nodes {}", e.max_nodes()),
                    format!("max_notifiers {}", e.max_notifiers()),
                    format!("max_listeners {}", e.max_listeners()),
                    format!("event_id_max_value {}", e.event_id_max_value()),
                    format!("deadline {}", or_none(e.deadline().map(|d| format!("{d:?}")))),
                    format!(
                        "notifier_created_event {}",
                        or_none(e.notifier_created_event().map(|v| v.as_value().to_string()))
                    ),
                    format!(
                        "notifier_dropped_event {}",
                        or_none(e.notifier_dropped_event().map(|v| v.as_value().to_string()))
                    ),
                    format!(
                        "notifier_dead_event {}",
                        or_none(e.notifier_dead_event().map(|v| v.as_value().to_string()))
                    ),
                ]);
                let none = "—".to_string();
                [format!("`{name}`"), "event".to_string(), none.clone(), none.clone(), none.clone(), none]
            }
            other => panic!("`{name}` is a {other:?} service"),
        };
        assert!(
            DOC.contains(&format!("iceoryx2 {}", s.iceoryx2_version())),
            "docs/wire.md must name the iceoryx2 version dyfosd uses, {}",
            s.iceoryx2_version()
        );
        expected.push(row.join(" | "));
    }
    assert!(services.is_empty(), "dyfosd creates services docs/wire.md does not list: {:?}", services.keys());
    same_rows("services", t, documented, expected);

    for (first, settings) in [("request-response setting", rr_settings), ("event setting", event_settings)] {
        let t = table(&all, first);
        let documented: Vec<String> = t
            .rows
            .iter()
            .map(|r| format!("{} {}", code(&r[0]), code(&r[1]).split_whitespace().next().unwrap_or("")))
            .collect();
        for s in settings {
            same_rows(first, t, documented.clone(), s);
        }
    }
}

/// §2's client port settings: without them a loan of 2 records fails (what a
/// literal reader hit first); with them a client loans every size a request may have.
#[test]
fn documented_client_port_settings_loan_every_size_a_request_may_have() {
    use dyfos_shared::wire::services;
    use iceoryx2::prelude::*;

    let all = tables(DOC);
    let t = table(&all, "client port");
    let header: Vec<&str> = t.header.iter().map(|h| code(h)).collect();
    assert_eq!(header, ["client port", "initial_max_slice_len", "allocation_strategy"], "docs/wire.md line {}", t.line);
    let setting = |service: &str| {
        let row = t.rows.iter().find(|r| code(&r[0]) == service).unwrap_or_else(|| panic!("no row for `{service}`"));
        let strategy = match code(&row[2]) {
            "PowerOfTwo" => AllocationStrategy::PowerOfTwo,
            "BestFit" => AllocationStrategy::BestFit,
            "Static" => AllocationStrategy::Static,
            other => panic!("docs/wire.md line {}: `{other}` is not an allocation strategy", t.line),
        };
        (int(&row[1]) as usize, strategy)
    };
    assert_eq!(t.rows.len(), 2, "docs/wire.md line {}: one row per service with slices", t.line);

    let (sandbox, _daemon) = Sandbox::with_daemon("wire-doc-loan");
    let (node, names) = sandbox.ipc_node();
    let services = services::Services::new(&node, &names);
    let rendezvous = services.rendezvous().expect("service name").open().expect("open rendezvous");
    let map = services.map().expect("service name").open().expect("open map");

    let plain = map.client_builder().create().expect("a client with iceoryx2's defaults");
    assert!(plain.loan_slice_uninit(1).is_ok());
    let Err(refused) = plain.loan_slice_uninit(2) else { panic!("by default a loan of 2 records fails") };
    assert!(format!("{refused:?}").contains("ExceedsMaxLoanSize"), "{refused:?}");

    let (len, strategy) = setting("<prefix>rendezvous");
    let client = rendezvous.client_builder().initial_max_slice_len(len).allocation_strategy(strategy).create().unwrap();
    for n in [0, 2, len, len + 1, MAX_INLINE_DELTAS] {
        assert!(client.loan_slice_uninit(n).is_ok(), "a rendezvous loan of {n} records");
    }
    let (len, strategy) = setting("<prefix>map");
    let client = map.client_builder().initial_max_slice_len(len).allocation_strategy(strategy).create().unwrap();
    for n in [0, 2, len, len + 1, MAX_DELTAS_PER_MESSAGE] {
        assert!(client.loan_slice_uninit(n).is_ok(), "a map loan of {n} records");
    }
}

/// What shared memory a daemon stopped by SIGTERM leaves is what docs/daemon.md and
/// this document say (iceoryx2's per-domain node counter), named as they name it
/// for the default domain.
#[test]
fn the_shared_memory_a_stopped_daemon_leaves_is_documented() {
    const DAEMON_DOC: &str = include_str!("../../../docs/daemon.md");
    let sandbox = Sandbox::new("wire-doc-shm");
    let mut daemon = sandbox.start_daemon(&[]);
    sandbox.client().stats(std::time::Duration::from_secs(30)).expect("stats");
    assert!(daemon.terminate().success(), "{}", daemon.log());
    let left: Vec<String> = std::fs::read_dir("/dev/shm")
        .expect("/dev/shm")
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with(&sandbox.domain))
        .collect();
    assert!(!left.is_empty(), "iceoryx2's node counter is expected to stay");
    for file in left {
        let default_domain = file.replacen(&sandbox.domain, "iox2_", 1);
        for (doc, text) in [("docs/daemon.md", DAEMON_DOC), ("docs/wire.md", DOC)] {
            assert!(
                text.contains(&format!("/dev/shm/{default_domain}")),
                "{doc} does not name `{file}` a stopped daemon left"
            );
        }
    }
}
