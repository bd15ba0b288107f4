//! The Box2D contact listener shared by PHYRE's and I-PHYRE's Box2D worlds: Box2D reports contacts per
//! pair of fixtures, the environments want them per pair of objects. Fixtures carry their object's
//! index as user data; the listener counts touching fixture pairs per object pair, so an object made of
//! several fixtures (a jar's walls, a capsule's box and end discs) touching another starts and ends one
//! contact, not several.
//!
//! It owns nothing else: building worlds, stepping them and turning the pairs into each environment's
//! contact-change type belong to the worlds (`phyre::box2d_world`, `iphyre::box2d_world`).

use std::collections::HashMap;

use box2d_rs::b2_contact::B2contactDynTrait;
use box2d_rs::b2_world_callbacks::B2contactListener;
use box2d_rs::b2rs_common::UserDataType;

/// Object-pair contact changes gathered from Box2D's begin/end callbacks.
#[derive(Debug, Default)]
pub(crate) struct PairContacts {
    /// Touching fixture pairs per object pair (smaller index first).
    active_pairs: HashMap<[usize; 2], u32>,
    /// Changes since the caller last took them: `(began, [a, b])`, `a < b`, in callback order.
    pub(crate) changes: Vec<(bool, [usize; 2])>,
}

impl PairContacts {
    /// The object pair of a contact, smaller index first; `None` for a fixture without an object or
    /// two fixtures of one object.
    fn pair<D: UserDataType<Fixture = usize>>(
        contact: &dyn B2contactDynTrait<D>,
    ) -> Option<[usize; 2]> {
        let base = contact.get_base();
        let a = base.get_fixture_a().borrow().get_user_data()?;
        let b = base.get_fixture_b().borrow().get_user_data()?;
        (a != b).then(|| [a.min(b), a.max(b)])
    }
}

impl<D: UserDataType<Fixture = usize>> B2contactListener<D> for PairContacts {
    fn begin_contact(&mut self, contact: &mut dyn B2contactDynTrait<D>) {
        let Some(key) = Self::pair(contact) else {
            return;
        };
        let count = self.active_pairs.entry(key).or_insert(0);
        *count += 1;
        if *count == 1 {
            self.changes.push((true, key));
        }
    }

    fn end_contact(&mut self, contact: &mut dyn B2contactDynTrait<D>) {
        let Some(key) = Self::pair(contact) else {
            return;
        };
        let count = self.active_pairs.entry(key).or_insert(0);
        if *count > 0 {
            *count -= 1;
            if *count == 0 {
                self.changes.push((false, key));
            }
        }
    }
}
