//! Handles: the table of live `dyfos_client` tokens, and the one entry every
//! function on a handle goes through, which checks the handle before anything else.
//!
//! A `dyfos_client *` is a token looked up in the table, never memory the library
//! reads. Its client sits in a mutex: one call at a time per handle, and
//! `dyfos_client_free` takes the client out under that mutex, so it waits for a
//! call in progress and any call still waiting for the handle then finds it freed.

use crate::status::{DYFOS_STATUS_NULL_PARAMETER, Failure, boundary, dyfos_status};
use ::dyfos_client::Client;
use std::collections::BTreeMap;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, PoisonError};
use std::time::Duration;

/// A connection to one `dyfosd` (opaque). Made by `dyfos_client_connect`, released
/// by `dyfos_client_free`. The pointer is a token the library looks up, never
/// memory it reads: a freed or made-up handle is refused with
/// `DYFOS_STATUS_NULL_PARAMETER`. Tokens are never reused within a process, so a
/// stale copy of a freed handle can never reach a newer connection.
pub struct dyfos_client {
    _opaque: [u8; 0],
}

/// One live handle: its client (taken out when freed) and its default timeout.
struct Slot {
    client: Mutex<Option<Client>>,
    timeout: Duration,
}

/// Every live handle by its token.
static CLIENTS: Mutex<BTreeMap<usize, Arc<Slot>>> = Mutex::new(BTreeMap::new());
/// The next token; never reused, so a stale token finds nothing.
static NEXT_TOKEN: AtomicUsize = AtomicUsize::new(1);

fn clients() -> MutexGuard<'static, BTreeMap<usize, Arc<Slot>>> {
    // The table holds no invariant a panic could break half-way.
    CLIENTS.lock().unwrap_or_else(PoisonError::into_inner)
}

fn not_live() -> Failure {
    Failure::new(
        DYFOS_STATUS_NULL_PARAMETER,
        "`client` is not a live handle: it was freed already, or did not come from dyfos_client_connect",
    )
}

/// Registers a connected client; its token, as the caller's handle.
pub(crate) fn register(client: Client, timeout: Duration) -> *mut dyfos_client {
    let token = NEXT_TOKEN.fetch_add(1, Ordering::Relaxed);
    clients().insert(token, Arc::new(Slot { client: Mutex::new(Some(client)), timeout }));
    std::ptr::without_provenance_mut(token)
}

/// A live handle, looked up.
pub(crate) struct Handle(Arc<Slot>);

impl Handle {
    fn lookup(client: *const dyfos_client) -> Result<Handle, Failure> {
        if client.is_null() {
            return Err(Failure::null("client"));
        }
        clients().get(&client.addr()).cloned().map(Handle).ok_or_else(not_live)
    }

    /// Runs `call` with the client and the call's timeout (`timeout_ms`, or the
    /// handle's when 0), after another thread's call on the same handle finishes.
    pub(crate) fn call<T>(
        &self,
        timeout_ms: u64,
        call: impl FnOnce(&mut Client, Duration) -> Result<T, Failure>,
    ) -> Result<T, Failure> {
        let timeout = if timeout_ms == 0 { self.0.timeout } else { Duration::from_millis(timeout_ms) };
        // A panic inside a call leaves the client usable (it is memory-safe Rust; at
        // worst its connection is dropped and re-opened by the next call).
        let mut guard = self.0.client.lock().unwrap_or_else(PoisonError::into_inner);
        let client = guard.as_mut().ok_or_else(|| {
            Failure::new(
                DYFOS_STATUS_NULL_PARAMETER,
                "`client` was freed by another thread while this call waited for it",
            )
        })?;
        call(client, timeout)
    }
}

/// The entry of every function that takes a handle: inside the panic boundary, the
/// handle is checked (NULL, freed, made up) before `body` looks at any other
/// argument, so a bad handle is `DYFOS_STATUS_NULL_PARAMETER` whatever else is wrong.
pub(crate) fn on_handle(
    client: *const dyfos_client,
    body: impl FnOnce(&Handle) -> Result<(), Failure>,
) -> dyfos_status {
    boundary(|| body(&Handle::lookup(client)?))
}

/// Releases a handle: removes it from the table, waits for a call in progress on
/// it, and closes its connection. NULL is a no-op.
pub(crate) fn free(client: *const dyfos_client) -> Result<(), Failure> {
    if client.is_null() {
        return Ok(());
    }
    let slot = clients().remove(&client.addr()).ok_or_else(|| {
        Failure::new(
            DYFOS_STATUS_NULL_PARAMETER,
            "`client` is not a live handle: it was freed already (double free), or did not come from dyfos_client_connect",
        )
    })?;
    // Waits for the call in progress (outside the table's lock: other handles go on).
    let taken = slot.client.lock().unwrap_or_else(PoisonError::into_inner).take();
    // Closing the ports happens here, after the lock is released: calls that were
    // waiting for the handle fail at once instead of after the close.
    drop(taken);
    Ok(())
}
