//! Declared publishers for the keys a process puts on every cycle (a robot's intention, a
//! worker's cycle outcome), declared on first use and kept.
//!
//! A one-off `put` on an undeclared key makes every Zenoh node on the way (this session, a
//! router, the receiving session) match the key against all the subscriptions it knows: with
//! one intention subscription per robot that is O(robots) per message, O(robots²) per cycle of
//! the fleet. A declared publisher declares its key once, and the nodes cache its route.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use protocol::WireMessage;
use zenoh::key_expr::OwnedKeyExpr;
use zenoh::pubsub::Publisher;
use zenoh::{Session, Wait};

use super::adapter::encode;
use super::error::{zenoh_err, FleetError};
use super::lock;

/// The declared publishers of one session, by key (see the module docs).
///
/// Its lock is a leaf, held only to look a publisher up or to declare one.
pub(crate) struct Publishers {
    session: Session,
    declared: Mutex<HashMap<OwnedKeyExpr, Arc<Publisher<'static>>>>,
}

impl Publishers {
    pub fn new(session: Session) -> Self {
        Self {
            session,
            declared: Mutex::new(HashMap::new()),
        }
    }

    /// Encodes `msg` and puts it on `key` through its publisher (declared now if it is the
    /// key's first message). Synchronous: called from the blocking pool.
    ///
    /// # Errors
    /// [`FleetError::Zenoh`], or the encoding's error.
    pub fn put<M: WireMessage>(&self, key: &OwnedKeyExpr, msg: &M) -> Result<(), FleetError> {
        let bytes = encode(msg)?;
        let known = lock(&self.declared).get(key).cloned();
        let publisher = match known {
            Some(p) => p,
            None => {
                // Declared outside the lock; should two cycles of one key race here, the
                // first one kept wins and the other publisher is dropped.
                let p = Arc::new(
                    self.session
                        .declare_publisher(key.clone())
                        .encoding(protocol::zenoh_io::encoding_for::<M>())
                        .wait()
                        .map_err(zenoh_err("declare a publisher"))?,
                );
                Arc::clone(lock(&self.declared).entry(key.clone()).or_insert(p))
            }
        };
        // The publisher carries the kind's encoding (a key always carries one kind).
        publisher.put(bytes).wait().map_err(zenoh_err("put"))
    }
}
