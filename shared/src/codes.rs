//! `codes!`: a closed set of numbered values (a status, an algorithm, a stop
//! reason, a noise model, a request mode) written once, as an enum whose every
//! variant carries its wire code, its name and its documentation.
//!
//! Everything else is generated from that one list: `ALL` in code order, `name` /
//! `from_name`, `code` / `TryFrom<u32>` (an unknown code is an [`UnknownCode`], never
//! an enum read from a peer's bits), `Display`, the list for error messages
//! (`0 dyfos, 1 dyfos-scipy, …`) and, on request, serde by name. The documents and
//! headers that restate a set are checked against `ALL` by their tests.
//!
//! ```
//! use dyfos_shared::answer::StopReason;
//!
//! assert_eq!(StopReason::try_from(3), Ok(StopReason::Deadline));
//! assert_eq!(StopReason::Deadline.name(), "deadline");
//! assert!(StopReason::try_from(9).is_err());
//! ```

/// An integer tag or code outside its set.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error)]
#[error("{field} = {value} is not a known code")]
pub struct UnknownCode {
    /// The field.
    pub field: &'static str,
    /// The value found.
    pub value: u32,
}

/// `codes! { #[attrs] pub enum Name("wire field") { #[doc] Variant = code, "name"; … } }`,
/// optionally `serde` after the field name: serialized as serde's derive would a
/// unit-only enum (the name in text formats, the code as the variant index), which
/// needs the codes to be `0..n` in order (a unit test checks every serde set).
macro_rules! codes {
    (
        $(#[$m:meta])*
        $vis:vis enum $ty:ident($field:literal $(, $serde:ident)?) {
            $($(#[$doc:meta])* $name:ident = $value:literal, $text:literal;)*
        }
    ) => {
        $(#[$m])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
        #[repr(u32)]
        $vis enum $ty {
            $($(#[$doc])* $name = $value,)*
        }

        impl $ty {
            /// Every value, in code order.
            pub const ALL: [$ty; [$($text),*].len()] = [$($ty::$name,)*];

            /// Every name, in code order.
            pub const NAMES: &'static [&'static str] = &[$($text),*];

            /// The wire code.
            pub const fn code(self) -> u32 {
                self as u32
            }

            /// The name, as files, flags, logs and the documents spell it.
            pub const fn name(self) -> &'static str {
                match self { $($ty::$name => $text,)* }
            }

            /// The value named `name`.
            pub fn from_name(name: &str) -> Option<Self> {
                match name {
                    $($text => Some($ty::$name),)*
                    _ => None,
                }
            }

            /// Every code and name for an error message: `0 paper, 1 anisotropic, 2 learned`.
            pub fn listing() -> String {
                [$(concat!(stringify!($value), " ", $text)),*].join(", ")
            }
        }

        impl TryFrom<u32> for $ty {
            type Error = $crate::codes::UnknownCode;
            fn try_from(value: u32) -> Result<Self, $crate::codes::UnknownCode> {
                match value {
                    $($value => Ok($ty::$name),)*
                    _ => Err($crate::codes::UnknownCode { field: $field, value }),
                }
            }
        }

        impl std::fmt::Display for $ty {
            fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
                f.write_str(self.name())
            }
        }

        $($crate::codes::codes!(@$serde $ty);)?
    };

    (@serde $ty:ident) => {
        impl serde::Serialize for $ty {
            fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
                s.serialize_unit_variant(stringify!($ty), self.code(), self.name())
            }
        }

        impl<'de> serde::Deserialize<'de> for $ty {
            fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
                d.deserialize_enum(stringify!($ty), $ty::NAMES, $crate::codes::EnumVisitor::<$ty>::new(stringify!($ty)))
            }
        }

        impl $crate::codes::Named for $ty {
            fn by_name(name: &str) -> Option<Self> {
                $ty::from_name(name)
            }
            fn by_code(code: u32) -> Option<Self> {
                $ty::try_from(code).ok()
            }
            const NAMES: &'static [&'static str] = $ty::NAMES;
        }
    };
}

pub(crate) use codes;

/// What the serde impls of `codes!` need of a set.
pub(crate) trait Named: Sized {
    /// The value named `name`.
    fn by_name(name: &str) -> Option<Self>;
    /// The value with code `code`.
    fn by_code(code: u32) -> Option<Self>;
    /// Every name, in code order.
    const NAMES: &'static [&'static str];
}

/// Deserializes a unit-only enum as serde's derive does: a variant identifier (a
/// name, or in binary formats the variant index) with no content.
pub(crate) struct EnumVisitor<T> {
    ty: &'static str,
    set: std::marker::PhantomData<T>,
}

impl<T> EnumVisitor<T> {
    /// For the enum named `ty`.
    pub(crate) fn new(ty: &'static str) -> Self {
        EnumVisitor { ty, set: std::marker::PhantomData }
    }
}

impl<'de, T: Named> serde::de::Visitor<'de> for EnumVisitor<T> {
    type Value = T;

    fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "enum {}", self.ty)
    }

    fn visit_enum<A: serde::de::EnumAccess<'de>>(self, data: A) -> Result<T, A::Error> {
        use serde::de::VariantAccess;
        let (Variant(value), access) = data.variant()?;
        access.unit_variant()?;
        Ok(value)
    }
}

/// One variant identifier of a [`Named`] set.
struct Variant<T>(T);

impl<'de, T: Named> serde::Deserialize<'de> for Variant<T> {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        d.deserialize_identifier(IdentifierVisitor(std::marker::PhantomData)).map(Variant)
    }
}

struct IdentifierVisitor<T>(std::marker::PhantomData<T>);

impl<'de, T: Named> serde::de::Visitor<'de> for IdentifierVisitor<T> {
    type Value = T;

    fn expecting(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str("variant identifier")
    }

    fn visit_u64<E: serde::de::Error>(self, v: u64) -> Result<T, E> {
        u32::try_from(v).ok().and_then(T::by_code).ok_or_else(|| {
            let expected = format!("variant index 0 <= i < {}", T::NAMES.len());
            E::invalid_value(serde::de::Unexpected::Unsigned(v), &expected.as_str())
        })
    }

    fn visit_str<E: serde::de::Error>(self, v: &str) -> Result<T, E> {
        T::by_name(v).ok_or_else(|| E::unknown_variant(v, T::NAMES))
    }

    fn visit_bytes<E: serde::de::Error>(self, v: &[u8]) -> Result<T, E> {
        match std::str::from_utf8(v) {
            Ok(s) => self.visit_str(s),
            Err(_) => Err(E::unknown_variant(&String::from_utf8_lossy(v), T::NAMES)),
        }
    }
}

#[cfg(test)]
mod tests {
    use crate::answer::{Algorithm, StopReason};
    use crate::params::ModelKind;
    use crate::wire::Status;
    use crate::wire::rendezvous::Mode;

    /// Serde's derive numbers variants `0..n` in order; the sets serialized by name
    /// must have the same codes so binary formats stay as they were.
    #[test]
    fn serde_sets_are_numbered_from_zero_in_order() {
        fn check<T: Copy + serde::Serialize + serde::de::DeserializeOwned + PartialEq + std::fmt::Debug>(
            all: &[T],
            code: fn(T) -> u32,
            name: fn(T) -> &'static str,
        ) {
            for (i, v) in all.iter().enumerate() {
                assert_eq!(code(*v) as usize, i, "{v:?}");
                let json = serde_json::to_value(v).unwrap();
                assert_eq!(json, serde_json::Value::from(name(*v)));
                assert_eq!(serde_json::from_value::<T>(json).unwrap(), *v);
            }
        }
        check(&Algorithm::ALL, Algorithm::code, Algorithm::name);
        check(&StopReason::ALL, StopReason::code, StopReason::name);
        check(&ModelKind::ALL, ModelKind::code, ModelKind::name);
    }

    #[test]
    fn a_wrong_name_gets_serdes_message_and_codes_list_every_value() {
        let e = serde_json::from_str::<ModelKind>("\"papr\"").unwrap_err().to_string();
        assert_eq!(e, "unknown variant `papr`, expected one of `paper`, `anisotropic`, `learned` at line 1 column 6");
        assert_eq!(Algorithm::listing(), "0 dyfos, 1 dyfos-scipy, 2 brute, 3 random, 4 center");
        assert_eq!(Mode::listing(), "0 solve, 1 check");
        for (i, s) in Status::ALL.iter().enumerate() {
            assert_eq!(Status::try_from(i as u32), Ok(*s));
        }
    }
}
