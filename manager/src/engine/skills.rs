//! The registered skills: one entry per board slot, the slots in registration order, and the
//! names seen before (a second registration of a name is a restart).

use super::Entry;
use skillfab_proto::board::MAX_SLOTS;
use std::collections::HashSet;

/// The manager's registry of skills.
pub(crate) struct Skills {
    /// By board slot.
    entries: Vec<Option<Entry>>,
    /// Occupied slots in registration order (lists and reports keep it).
    order: Vec<usize>,
    /// Names that have registered before.
    seen: HashSet<String>,
}

impl Skills {
    pub(crate) fn new() -> Skills {
        Skills {
            entries: (0..MAX_SLOTS).map(|_| None).collect(),
            order: Vec::new(),
            seen: HashSet::new(),
        }
    }

    /// The skill in slot `s`.
    pub(crate) fn get(&self, s: usize) -> Option<&Entry> {
        self.entries.get(s)?.as_ref()
    }

    /// The skill in slot `s`, to change.
    pub(crate) fn get_mut(&mut self, s: usize) -> Option<&mut Entry> {
        self.entries.get_mut(s)?.as_mut()
    }

    /// The slot of the skill called `name`.
    pub(crate) fn slot_of(&self, name: &str) -> Option<usize> {
        self.in_order()
            .find(|(_, e)| e.decl.name == name)
            .map(|(s, _)| s)
    }

    /// Slots and skills in registration order.
    pub(crate) fn in_order(&self) -> impl Iterator<Item = (usize, &Entry)> + '_ {
        self.order.iter().filter_map(|&s| Some((s, self.get(s)?)))
    }

    /// Every registered skill (slot order).
    pub(crate) fn all(&self) -> impl Iterator<Item = &Entry> + Clone + '_ {
        self.entries.iter().flatten()
    }

    /// Registers `entry` in slot `s`; returns whether its name registered before (a restart).
    pub(crate) fn insert(&mut self, s: usize, entry: Entry) -> bool {
        let restarted = !self.seen.insert(entry.decl.name.clone());
        self.entries[s] = Some(entry);
        self.order.retain(|&o| o != s);
        self.order.push(s);
        restarted
    }

    /// Takes the skill out of slot `s`.
    pub(crate) fn remove(&mut self, s: usize) -> Option<Entry> {
        let entry = self.entries.get_mut(s)?.take()?;
        self.order.retain(|&o| o != s);
        Some(entry)
    }
}
