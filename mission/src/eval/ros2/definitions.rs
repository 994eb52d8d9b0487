//! The `ros2msg` schemas of the ROS 2 profile: each message type's definition
//! followed by those of every type it uses, exactly as rosbag2 (jazzy) writes them
//! into an MCAP file (`rosbag2_cpp::LocalMessageDefinitionSource::get_full_text`):
//! the root's `.msg` text, then for each dependency, depth first and in sorted
//! order, a line of 80 `=`, a `MSG: pkg/Type` line and that type's `.msg` text,
//! each type once.
//!
//! The `.msg` files in `msg/` are ROS 2 jazzy's own, byte for byte (see
//! `msg/README.md`); dyfos's own are those of the `dyfos_msgs` package
//! (`ros/dyfos_msgs/msg/`), so the file's schemas and the installed package agree.

use std::collections::{BTreeSet, HashSet};

/// Every `.msg` this profile uses, by `pkg/Type`.
const MSGS: [(&str, &str); 23] = [
    ("builtin_interfaces/Duration", include_str!("msg/builtin_interfaces/Duration.msg")),
    ("builtin_interfaces/Time", include_str!("msg/builtin_interfaces/Time.msg")),
    ("dyfos_msgs/Ape", include_str!("../../../../ros/dyfos_msgs/msg/Ape.msg")),
    ("dyfos_msgs/Measurement", include_str!("../../../../ros/dyfos_msgs/msg/Measurement.msg")),
    ("dyfos_msgs/RendezvousAnswer", include_str!("../../../../ros/dyfos_msgs/msg/RendezvousAnswer.msg")),
    ("geometry_msgs/Point", include_str!("msg/geometry_msgs/Point.msg")),
    ("geometry_msgs/Pose", include_str!("msg/geometry_msgs/Pose.msg")),
    ("geometry_msgs/PoseStamped", include_str!("msg/geometry_msgs/PoseStamped.msg")),
    ("geometry_msgs/PoseWithCovariance", include_str!("msg/geometry_msgs/PoseWithCovariance.msg")),
    ("geometry_msgs/PoseWithCovarianceStamped", include_str!("msg/geometry_msgs/PoseWithCovarianceStamped.msg")),
    ("geometry_msgs/Quaternion", include_str!("msg/geometry_msgs/Quaternion.msg")),
    ("geometry_msgs/Transform", include_str!("msg/geometry_msgs/Transform.msg")),
    ("geometry_msgs/TransformStamped", include_str!("msg/geometry_msgs/TransformStamped.msg")),
    ("geometry_msgs/Vector3", include_str!("msg/geometry_msgs/Vector3.msg")),
    ("nav_msgs/Path", include_str!("msg/nav_msgs/Path.msg")),
    ("sensor_msgs/CompressedImage", include_str!("msg/sensor_msgs/CompressedImage.msg")),
    ("std_msgs/ColorRGBA", include_str!("msg/std_msgs/ColorRGBA.msg")),
    ("std_msgs/Header", include_str!("msg/std_msgs/Header.msg")),
    ("tf2_msgs/TFMessage", include_str!("msg/tf2_msgs/TFMessage.msg")),
    ("visualization_msgs/Marker", include_str!("msg/visualization_msgs/Marker.msg")),
    ("visualization_msgs/MarkerArray", include_str!("msg/visualization_msgs/MarkerArray.msg")),
    ("visualization_msgs/MeshFile", include_str!("msg/visualization_msgs/MeshFile.msg")),
    ("visualization_msgs/UVCoordinate", include_str!("msg/visualization_msgs/UVCoordinate.msg")),
];

/// rosbag2's limit on the depth of nested types.
const MAX_DEPTH: u32 = 50;

/// The types rosbag2 does not look up.
const PRIMITIVES: [&str; 14] = [
    "bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32", "uint32", "int64",
    "uint64", "string",
];

/// Package and type of `pkg/Type` or `pkg/msg/Type`.
fn split(name: &str) -> Option<(&str, &str)> {
    match name.split('/').collect::<Vec<_>>()[..] {
        [package, ty] | [package, "msg", ty] => Some((package, ty)),
        _ => None,
    }
}

/// The `.msg` text of `pkg/Type` or `pkg/msg/Type`.
pub(crate) fn msg(name: &str) -> Option<&'static str> {
    let (package, ty) = split(name)?;
    MSGS.iter().find(|(n, _)| split(n) == Some((package, ty))).map(|(_, text)| *text)
}

/// ECMAScript's `\s`, as `std::regex` reads it in the C locale.
fn is_space(b: u8) -> bool {
    matches!(b, b' ' | b'\t' | b'\n' | 0x0b | 0x0c | b'\r')
}

fn is_type_char(b: u8) -> bool {
    b.is_ascii_alphanumeric() || b == b'_' || b == b'/'
}

/// The field types of a `.msg` text, found as rosbag2 finds them: every match of
/// `(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:\[[^\]]*\])?\s+`, searched one after the other
/// (a match ends after the whitespace that follows the type, so a line holding a
/// type alone swallows the line break before the next one).
fn field_types(text: &str) -> Vec<&str> {
    let b = text.as_bytes();
    // The match whose text starts at `start` (after `^` or a line break).
    let try_at = |start: usize| -> Option<(usize, usize, usize)> {
        let mut i = start;
        while i < b.len() && is_space(b[i]) {
            i += 1;
        }
        let first = i;
        while i < b.len() && is_type_char(b[i]) {
            i += 1;
        }
        let last = i;
        if first == last {
            return None;
        }
        if b.get(i) == Some(&b'[')
            && let Some(close) = b[i + 1..].iter().position(|&c| c == b']')
            && b.get(i + close + 2).is_some_and(|&c| is_space(c))
        {
            i += close + 2;
        }
        if !b.get(i).is_some_and(|&c| is_space(c)) {
            return None;
        }
        while i < b.len() && is_space(b[i]) {
            i += 1;
        }
        Some((first, last, i))
    };
    let mut types = Vec::new();
    let mut from = 0;
    loop {
        // `^` matches at the very start only; later matches begin at a line break.
        let starts = (from == 0)
            .then_some(0)
            .into_iter()
            .chain(b.iter().enumerate().skip(from).filter(|&(_, &c)| c == b'\n').map(|(i, _)| i + 1));
        match starts.filter_map(try_at).next() {
            Some((first, last, end)) => {
                types.push(&text[first..last]);
                from = end;
            }
            None => return types,
        }
    }
}

/// The types a `.msg` text of `package` uses, as `pkg/Type`, sorted.
fn dependencies(text: &str, package: &str) -> BTreeSet<String> {
    field_types(text)
        .into_iter()
        .filter(|t| !PRIMITIVES.contains(t))
        .map(|t| if t.contains('/') { t.to_string() } else { format!("{package}/{t}") })
        .collect()
}

/// The separator rosbag2 writes before the definition of `name`.
fn delimiter(name: &str) -> String {
    format!("{}\nMSG: {name}\n", "=".repeat(80))
}

/// The full `ros2msg` definition of `root` (`pkg/msg/Type`), as rosbag2 writes it.
pub fn full_text(root: &str) -> Result<String, String> {
    fn append(name: &str, depth: u32, seen: &mut HashSet<String>) -> Result<String, String> {
        if depth == 0 {
            return Err(format!("types nested too deep under {name}"));
        }
        let (package, _) = split(name).ok_or_else(|| format!("`{name}` is not a message type"))?;
        let text = msg(name).ok_or_else(|| format!("no definition of {name}"))?;
        let mut result = text.to_string();
        for dependency in dependencies(text, package) {
            if seen.insert(dependency.clone()) {
                result.push('\n');
                result.push_str(&delimiter(&dependency));
                result.push_str(&append(&dependency, depth - 1, seen)?);
            }
        }
        Ok(result)
    }
    append(root, MAX_DEPTH, &mut HashSet::new())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A root type's text: its own definition, then each type it uses, depth first
    /// in sorted field order and once each, after a rosbag2 separator.
    #[test]
    fn a_root_is_followed_by_its_types_depth_first_once_each() {
        let cases: [(&str, &[&str]); 2] = [
            (
                "geometry_msgs/PoseStamped",
                &[
                    "geometry_msgs/Pose",
                    "geometry_msgs/Point",
                    "geometry_msgs/Quaternion",
                    "std_msgs/Header",
                    "builtin_interfaces/Time",
                ],
            ),
            // Marker uses Header directly and through CompressedImage, which comes first.
            (
                "visualization_msgs/MarkerArray",
                &[
                    "visualization_msgs/Marker",
                    "builtin_interfaces/Duration",
                    "geometry_msgs/Point",
                    "geometry_msgs/Pose",
                    "geometry_msgs/Quaternion",
                    "geometry_msgs/Vector3",
                    "sensor_msgs/CompressedImage",
                    "std_msgs/Header",
                    "builtin_interfaces/Time",
                    "std_msgs/ColorRGBA",
                    "visualization_msgs/MeshFile",
                    "visualization_msgs/UVCoordinate",
                ],
            ),
        ];
        for (root, uses) in cases {
            let sections = uses.iter().map(|name| format!("\n{}{}", delimiter(name), msg(name).unwrap()));
            let expected: String = std::iter::once(msg(root).unwrap().to_string()).chain(sections).collect();
            assert_eq!(full_text(&root.replacen('/', "/msg/", 1)).unwrap(), expected, "{root}");
        }
        // The shape of a rosbag2 file: a blank line before each separator.
        assert!(full_text("geometry_msgs/msg/PoseStamped").unwrap().contains(
            "Pose pose\n\n================================================================================\nMSG: geometry_msgs/Pose\n# A representation"
        ));
    }

    #[test]
    fn field_types_are_read_like_rosbag2s_pattern() {
        let text = "# comment Pose\nint32 A=1\n  Header header # note\nfloat64[36] c\nPoint[<=3] p\nstring<=5 s\nlone/Type\nskipped/Type x\nlast/Type y";
        // Comments and bounded strings hold no type; `lone/Type` is followed by the
        // line break itself, which the match takes, so the next line is not read.
        assert_eq!(field_types(text), ["int32", "Header", "float64", "Point", "lone/Type", "last/Type"]);
        assert_eq!(
            dependencies(text, "pkg").into_iter().collect::<Vec<_>>(),
            ["last/Type", "lone/Type", "pkg/Header", "pkg/Point"]
        );
        // A type with nothing after it, at the very end, is not matched.
        assert_eq!(field_types("Pose"), Vec::<&str>::new());
        assert!(full_text("geometry_msgs/msg/Nothing").unwrap_err().contains("no definition"));
    }
}
