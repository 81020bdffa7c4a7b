//! The registered skills: one entry per board slot, the slots in registration order, the
//! names seen before (a second registration of a name is a restart), and what clients set for
//! each name, which a restarted instance gets back.

use super::Entry;
use skillfab_proto::board::MAX_SLOTS;
use skillfab_proto::control::GaveUpInfo;
use skillfab_proto::decl::SkillDecl;
use skillfab_proto::param::ParamValue;
use std::collections::{BTreeMap, HashMap};

/// What clients set for a skill, kept by name across restarts of its process.
#[derive(Debug, Clone, Default, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct Kept {
    /// Activation, once a client changed it.
    pub(crate) active: Option<bool>,
    /// Parameters clients set, in the order they were first set.
    pub(crate) params: Vec<(String, ParamValue)>,
    /// Priority, once a client changed it.
    pub(crate) priority: Option<i32>,
    /// Activations by clients so far: the activation number on the board is one more (the
    /// first, from the launch, is 1). A restarted process of the name gets the same number.
    pub(crate) activations: u32,
    /// A client wants it (`Request::Want`): it runs with everything it reads from.
    pub(crate) wanted: bool,
    /// Activated on demand: a wanted skill reads from it; released when none does.
    pub(crate) demanded: bool,
}

/// The manager's registry of skills.
pub(crate) struct Skills {
    /// Registered processes found dead so far.
    pub(crate) deaths: u64,
    /// The processes `skillfab up` gave up restarting and that have not registered since.
    pub(crate) gave_up: BTreeMap<String, GaveUpInfo>,
    /// By board slot.
    entries: Vec<Option<Entry>>,
    /// Occupied slots in registration order (lists and reports keep it).
    order: Vec<usize>,
    /// The last declaration of every name that registered (a name seen before is a restart;
    /// while it is away, requests for it are checked against this and kept).
    last: HashMap<String, SkillDecl>,
    /// What clients set, by skill name.
    kept: HashMap<String, Kept>,
}

impl Skills {
    pub(crate) fn new() -> Skills {
        Skills {
            deaths: 0,
            gave_up: BTreeMap::new(),
            entries: (0..MAX_SLOTS).map(|_| None).collect(),
            order: Vec::new(),
            last: HashMap::new(),
            kept: HashMap::new(),
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
        let restarted = self
            .last
            .insert(entry.decl.name.clone(), entry.decl.clone())
            .is_some();
        self.entries[s] = Some(entry);
        self.order.retain(|&o| o != s);
        self.order.push(s);
        restarted
    }

    /// The declaration of `name` if it registered before but is not registered now (its
    /// process died or left, and may come back).
    pub(crate) fn away(&self, name: &str) -> Option<&SkillDecl> {
        self.slot_of(name).is_none().then(|| self.last.get(name))?
    }

    /// The declaration of `name`: the live instance's, else (away) its last one.
    pub(crate) fn decl(&self, name: &str) -> Option<&SkillDecl> {
        match self.slot_of(name) {
            Some(s) => self.get(s).map(|e| &e.decl),
            None => self.last.get(name),
        }
    }

    /// What clients set for `name`, to change (a client sets something).
    pub(crate) fn keep(&mut self, name: &str) -> &mut Kept {
        self.kept.entry(name.to_string()).or_default()
    }

    /// What the board says for `name`'s activation: 0 inactive, or its activation number.
    pub(crate) fn activation(&self, name: &str, active: bool) -> u32 {
        if active {
            1 + self.kept(name).map_or(0, |k| k.activations)
        } else {
            0
        }
    }

    /// Whether `name` is active: registered and active, or away and kept active.
    pub(crate) fn is_active(&self, name: &str) -> bool {
        match self.slot_of(name).and_then(|s| self.get(s)) {
            Some(e) => e.active,
            None => self.kept(name).and_then(|k| k.active) == Some(true),
        }
    }

    /// The declarations of every skill and device known: the registered ones and the ones
    /// away.
    pub(crate) fn known(&self) -> Vec<&SkillDecl> {
        let live = self.all().map(|e| &e.decl);
        let away = self
            .last
            .values()
            .filter(|d| self.slot_of(&d.name).is_none());
        live.chain(away).collect()
    }

    /// The names clients set a mark on (`wanted`, `demanded`), sorted.
    pub(crate) fn marked(&self, mark: impl Fn(&Kept) -> bool) -> Vec<String> {
        let mut names: Vec<String> = self
            .kept
            .iter()
            .filter(|(_, k)| mark(k))
            .map(|(n, _)| n.clone())
            .collect();
        names.sort();
        names
    }

    /// What clients set for `name`, if anything.
    pub(crate) fn kept(&self, name: &str) -> Option<&Kept> {
        self.kept.get(name)
    }

    /// What clients set and the last declarations, by name, for the state file.
    pub(crate) fn saved(&self) -> (BTreeMap<String, Kept>, BTreeMap<String, SkillDecl>) {
        let kept = self.kept.iter().map(|(k, v)| (k.clone(), v.clone()));
        let last = self.last.iter().map(|(k, v)| (k.clone(), v.clone()));
        (kept.collect(), last.collect())
    }

    /// Takes over a previous manager's: every name in `last` registers as a restart and gets
    /// what `kept` holds for it.
    pub(crate) fn restore(
        &mut self,
        kept: BTreeMap<String, Kept>,
        last: BTreeMap<String, SkillDecl>,
    ) {
        self.kept.extend(kept);
        self.last.extend(last);
    }

    /// Takes the skill out of slot `s`.
    pub(crate) fn remove(&mut self, s: usize) -> Option<Entry> {
        let entry = self.entries.get_mut(s)?.take()?;
        self.order.retain(|&o| o != s);
        Some(entry)
    }
}
