//! `scheduling.cpu_latency_us`: a number of µs or `"off"`, in TOML and JSON alike.

use serde::{Deserialize, Serialize};

/// `scheduling.cpu_latency_us`: µs, or `"off"`.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum CpuLatencyTarget {
    /// Idle cores wake within this many µs while traffic is steady.
    Micros(u32),
    /// No request: idle cores wake as the kernel decides.
    Off,
}

impl CpuLatencyTarget {
    /// The target in µs; `None` for `"off"`.
    pub fn micros(self) -> Option<u32> {
        match self {
            CpuLatencyTarget::Micros(us) => Some(us),
            CpuLatencyTarget::Off => None,
        }
    }
}

impl Serialize for CpuLatencyTarget {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        match self {
            CpuLatencyTarget::Micros(us) => s.serialize_u32(*us),
            CpuLatencyTarget::Off => s.serialize_str("off"),
        }
    }
}

impl<'de> Deserialize<'de> for CpuLatencyTarget {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct Visitor;
        impl serde::de::Visitor<'_> for Visitor {
            type Value = CpuLatencyTarget;
            fn expecting(&self, f: &mut std::fmt::Formatter) -> std::fmt::Result {
                f.write_str("a number of µs or \"off\"")
            }
            fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<Self::Value, E> {
                u32::try_from(v)
                    .map(CpuLatencyTarget::Micros)
                    .map_err(|_| E::invalid_value(serde::de::Unexpected::Unsigned(v), &self))
            }
            fn visit_i64<E: serde::de::Error>(self, v: i64) -> Result<Self::Value, E> {
                u64::try_from(v)
                    .map_err(|_| E::invalid_value(serde::de::Unexpected::Signed(v), &self))
                    .and_then(|v| self.visit_u64(v))
            }
            fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<Self::Value, E> {
                match v {
                    "off" => Ok(CpuLatencyTarget::Off),
                    other => Err(E::invalid_value(serde::de::Unexpected::Str(other), &self)),
                }
            }
        }
        d.deserialize_any(Visitor)
    }
}
