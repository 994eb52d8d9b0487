// The library's version and ABI version. Also read by build.rs (through `include!`,
// so no inner doc comment here), which gives libdyfos.so the SONAME
// `libdyfos.so.<DYFOS_ABI_VERSION>`.

/// The ABI version of this header: raised at every change that breaks programs
/// built against an older header (a changed signature, struct layout or meaning).
/// `libdyfos.so`'s SONAME is `libdyfos.so.<DYFOS_ABI_VERSION>`, so a program runs
/// only with a library of the ABI it was built for; `dyfos_abi_version()` says
/// which one a loaded library implements.
pub const DYFOS_ABI_VERSION: u32 = 1u32;

/// Major version of the dyfos release this header comes from.
pub const DYFOS_VERSION_MAJOR: u32 = 0u32;

/// Minor version of the dyfos release this header comes from.
pub const DYFOS_VERSION_MINOR: u32 = 1u32;

/// Patch version of the dyfos release this header comes from.
pub const DYFOS_VERSION_PATCH: u32 = 0u32;
