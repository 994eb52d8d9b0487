//! The flags every mission process shares: the rover, the viewer and the link
//! between hosts name a mission's topics the same way.

/// The flags that name a mission's topics, the same in `dyfos-rover`, `dyfos-viewer`
/// and `dyfos-link` (`#[command(flatten)]`): the two ends of a mission, and the link
/// between hosts, find each other by them.
#[derive(Debug, Clone, clap::Args)]
pub struct TopicArgs {
    /// Service-name prefix of the mission topics (and of the daemon, for the rover and viewer).
    #[arg(long, default_value = dyfos_shared::wire::DEFAULT_PREFIX)]
    pub prefix: String,
    /// iceoryx2 domain (file prefix), as given to `dyfosd --domain`.
    #[arg(long)]
    pub domain: Option<String>,
    /// Mission name (letters, digits, `-`, `_`, `.`): the rover, its viewer and their links use the same.
    #[arg(long, default_value = "default")]
    pub mission_name: String,
}

impl TopicArgs {
    /// Where the mission's topics are.
    pub fn topics(&self) -> crate::mission::topics::TopicsConfig {
        crate::mission::topics::TopicsConfig {
            prefix: self.prefix.clone(),
            domain: self.domain.clone(),
            mission: self.mission_name.clone(),
        }
    }
}
