//! A convention every dyfos command line keeps: a number our commands print can be
//! pasted back into any of their flags. clap takes `-7.08e-06` for a flag of its
//! own, even with `allow_negative_numbers` (it knows `-7.08`, not exponents), so
//! every flag that takes numbers sets `allow_hyphen_values`.
//!
//! ```
//! #[derive(clap::Parser)]
//! struct Cli {
//!     #[arg(long, num_args = 2, allow_hyphen_values = true)]
//!     sun: Vec<f64>,
//! }
//! use clap::{CommandFactory, Parser};
//! assert!(dyfos_process::cli::numeric_flags_refusing_signs(&Cli::command()).is_empty());
//! assert_eq!(Cli::parse_from(["cli", "--sun", "-7.08e-06", "-0.0"]).sun[0], -7.08e-06);
//! ```

/// The flags of `cmd` and its subcommands (as `command --flag`) that take `f64`
/// values but would refuse `-7.08e-06`: those without `allow_hyphen_values`.
pub fn numeric_flags_refusing_signs(cmd: &clap::Command) -> Vec<String> {
    let f64_parser = clap::Arg::new("f64").value_parser(clap::value_parser!(f64));
    let f64_id = f64_parser.get_value_parser().type_id();
    let mut out: Vec<String> = cmd
        .get_arguments()
        .filter(|a| a.get_value_parser().type_id() == f64_id && !a.is_allow_hyphen_values_set())
        .map(|a| format!("{} --{}", cmd.get_name(), a.get_long().unwrap_or(a.get_id().as_str())))
        .collect();
    for sub in cmd.get_subcommands() {
        out.extend(numeric_flags_refusing_signs(sub));
    }
    out
}

/// Panics, naming them, if [`numeric_flags_refusing_signs`] finds any: the test
/// every dyfos binary runs on its own command line.
pub fn assert_numeric_flags_take_signs(cmd: &clap::Command) {
    let refusing = numeric_flags_refusing_signs(cmd);
    assert!(refusing.is_empty(), "set allow_hyphen_values on {refusing:?}");
}

/// The test every dyfos binary runs on its command line `$cli` (its `clap::Parser`):
/// every number a dyfos command prints can be pasted back, `-7.08e-06` included.
/// Expands to a `#[cfg(test)]` module `cli_tests`.
#[macro_export]
macro_rules! numeric_flags_test {
    ($cli:ty) => {
        #[cfg(test)]
        mod cli_tests {
            #[test]
            fn every_numeric_flag_takes_negative_numbers_in_any_notation() {
                $crate::cli::assert_numeric_flags_take_signs(&<$cli as clap::CommandFactory>::command());
            }
        }
    };
}
