//! Services whose creator died while creating them.
//!
//! iceoryx2 (0.10) creates a service by first writing its static file, owner
//! read-write, and then marking it read-only once the service is whole. A process
//! killed between the two leaves a file every later opener reads as "being
//! created" (`HangsInCreation`) for good, and iceoryx2's cleanup of dead nodes
//! skips it: the service name is unusable until someone deletes the file by hand.
//! A link or daemon restarted after a `kill -9` at start-up would fail forever.
//!
//! The creator writes a service tag in its node's directory before the static
//! file, and the cleanup of a dead node removes its tags. So after that cleanup, a
//! static file still being created with no tag in any node's directory has no
//! living creator, and removing it lets the next open create the service afresh.

use iceoryx2::config::Config;
use iceoryx2::node::Node;
use iceoryx2::service::Service;
use iceoryx2::service::messaging_pattern::MessagingPattern;
use iceoryx2::service::service_hash::ServiceHash;
use iceoryx2::service::service_name::ServiceName;
use std::io;
use std::os::unix::fs::PermissionsExt;
use std::path::PathBuf;

/// The permissions of a static file still being created (iceoryx2's
/// `INIT_PERMISSIONS`); a finished one is read-only.
const BEING_CREATED: u32 = 0o600;

/// Where iceoryx2 keeps the static file of service `name` (`pattern`) under `config`.
pub fn static_file<S: Service>(config: &Config, name: &ServiceName, pattern: MessagingPattern) -> PathBuf {
    let global = &config.global;
    PathBuf::from(global.service_dir().to_string()).join(file_name::<S>(
        config,
        name,
        pattern,
        &global.service.static_config_storage_suffix,
    ))
}

/// The name of the tag a node's directory holds for each service it created or opened.
fn tag_name<S: Service>(config: &Config, name: &ServiceName, pattern: MessagingPattern) -> String {
    file_name::<S>(config, name, pattern, &config.global.node.service_tag_suffix)
}

fn file_name<S: Service>(
    config: &Config,
    name: &ServiceName,
    pattern: MessagingPattern,
    suffix: &dyn std::fmt::Display,
) -> String {
    let hash = ServiceHash::new::<S::ServiceNameHasher>(name, pattern);
    format!("{}{}{suffix}", config.global.prefix, hash.as_str())
}

/// Removes the static file of service `name` (`pattern`) if its creator died
/// before finishing it. Cleans up dead nodes first, so a dead creator's tag is gone.
/// Returns whether a file was removed; a service being created by a living
/// process, a finished one or a missing one are left alone.
pub fn remove_abandoned_creation<S: Service>(
    node: &Node<S>,
    name: &ServiceName,
    pattern: MessagingPattern,
) -> io::Result<bool> {
    node.try_cleanup_dead_nodes();
    let config = node.config();
    let static_file = static_file::<S>(config, name, pattern);
    let metadata = match std::fs::metadata(&static_file) {
        Ok(m) => m,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(false),
        Err(e) => return Err(e),
    };
    if !metadata.is_file() || metadata.permissions().mode() & 0o777 != BEING_CREATED {
        return Ok(false);
    }
    let tag = tag_name::<S>(config, name, pattern);
    let nodes = match std::fs::read_dir(config.global.node_dir().to_string()) {
        Ok(nodes) => nodes,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return remove(&static_file),
        Err(e) => return Err(e),
    };
    for node_dir in nodes {
        if node_dir?.path().join(&tag).exists() {
            return Ok(false);
        }
    }
    remove(&static_file)
}

/// [`remove_abandoned_creation`] for a process that could not open `name`: logs
/// what it removed, or why it could not check, and returns whether opening again
/// is worth it.
#[cfg(feature = "logging")]
pub fn recover<S: Service>(node: &Node<S>, name: &ServiceName, pattern: MessagingPattern) -> bool {
    match remove_abandoned_creation(node, name, pattern) {
        Ok(true) => {
            tracing::warn!(service = %name, "removed what a process killed while creating this service left behind");
            true
        }
        Ok(false) => false,
        Err(e) => {
            tracing::warn!(service = %name, "cannot check whether this service's creator died: {e}");
            false
        }
    }
}

fn remove(file: &std::path::Path) -> io::Result<bool> {
    match std::fs::remove_file(file) {
        Ok(()) => Ok(true),
        Err(e) if e.kind() == io::ErrorKind::NotFound => Ok(false),
        Err(e) => Err(e),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use iceoryx2::prelude::*;
    use iceoryx2::service::builder::event::{EventOpenError, EventOpenOrCreateError};
    use std::fs::{File, Permissions};

    type Ipc = iceoryx2::service::ipc::Service;

    fn node(domain: &str) -> Node<Ipc> {
        let mut config = iceoryx2::config::Config::default();
        config.global.prefix = iceoryx2::prelude::FileName::new(domain.as_bytes()).unwrap();
        NodeBuilder::new().config(&config).create::<Ipc>().unwrap()
    }

    /// A node of a domain of this test's own (`test` and the pid), and the file a
    /// process killed while creating service `name` left behind there.
    fn half_created(test: &str, name: &str, pattern: MessagingPattern) -> (Node<Ipc>, ServiceName, PathBuf) {
        let node = node(&format!("{test}{}", std::process::id()));
        let name = ServiceName::new(name).unwrap();
        let file = static_file::<Ipc>(node.config(), &name, pattern);
        std::fs::create_dir_all(file.parent().unwrap()).unwrap();
        File::create(&file).unwrap();
        std::fs::set_permissions(&file, Permissions::from_mode(BEING_CREATED)).unwrap();
        (node, name, file)
    }

    #[test]
    fn a_service_whose_creator_died_is_created_afresh() {
        let (node, name, file) = half_created("abandon", "dyfos-test/abandoned", MessagingPattern::Event);
        let hangs = node.service_builder(&name).event().open_or_create();
        assert!(
            matches!(hangs, Err(EventOpenOrCreateError::EventOpenError(EventOpenError::HangsInCreation))),
            "{hangs:?}"
        );
        assert!(remove_abandoned_creation(&node, &name, MessagingPattern::Event).unwrap());
        assert!(!file.exists());
        let service = node.service_builder(&name).event().open_or_create();
        assert!(service.is_ok(), "{service:?}");
        // A finished service is left alone.
        assert!(!remove_abandoned_creation(&node, &name, MessagingPattern::Event).unwrap());
        assert!(node.service_builder(&name).event().open().is_ok());
    }

    #[test]
    fn a_service_a_living_node_is_creating_is_left_alone() {
        let (node, name, file) =
            half_created("creating", "dyfos-test/being-created", MessagingPattern::PublishSubscribe);
        // The living creator's tag, written before the static file.
        let global = &node.config().global;
        let node_dir = std::fs::read_dir(global.node_dir().to_string())
            .unwrap()
            .map(|d| d.unwrap().path())
            .find(|d| d.join(format!("{}node{}", global.prefix, global.node.static_config_suffix)).exists())
            .expect("the living node's directory");
        let tag = node_dir.join(tag_name::<Ipc>(node.config(), &name, MessagingPattern::PublishSubscribe));
        File::create(&tag).unwrap();
        assert!(!remove_abandoned_creation(&node, &name, MessagingPattern::PublishSubscribe).unwrap());
        assert!(file.exists());
        // The same file for the other pattern is another service.
        assert!(!remove_abandoned_creation(&node, &name, MessagingPattern::Event).unwrap());
        std::fs::remove_file(&tag).unwrap();
        assert!(remove_abandoned_creation(&node, &name, MessagingPattern::PublishSubscribe).unwrap());
        assert!(!file.exists());
    }
}
