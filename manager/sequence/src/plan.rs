//! Reading a plan: BehaviorTree.CPP v4 XML (the format of Nav2 and Groot) into a checked
//! description of its trees ([`Spec`]). Every mistake is refused with its line and what
//! would be right; nothing runs until the whole file is sound.

use std::collections::BTreeMap;
use std::time::Duration;

/// A plan that cannot be run, with where.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PlanError {
    /// The plan file (or `<plan>`).
    pub file: String,
    /// The line (1-based; 0: the file as a whole).
    pub line: u32,
    /// What is wrong.
    pub reason: String,
}

impl std::fmt::Display for PlanError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match (self.file.as_str(), self.line) {
            ("", _) => write!(f, "{}", self.reason),
            (file, 0) => write!(f, "{file}: {}", self.reason),
            (file, line) => write!(f, "{file}:{line}: {}", self.reason),
        }
    }
}

impl std::error::Error for PlanError {}

/// How deep elements may nest, and how many nodes a tree may have with its sub-trees
/// inlined: a plan beyond these is refused rather than run out of stack or memory.
const MAX_DEPTH: usize = 64;
const MAX_NODES: usize = 100_000;

/// One node of a tree, as written.
#[derive(Debug, Clone, PartialEq)]
pub struct Spec {
    /// What the node does.
    pub kind: Kind,
    /// Its `name` attribute, or its element name (what the step log calls it).
    pub name: String,
    /// Where it is written.
    pub line: u32,
}

/// The nodes a plan can use: BehaviorTree.CPP's control nodes and decorators, and the
/// fabric's actions.
#[derive(Debug, Clone, PartialEq)]
pub enum Kind {
    /// Children in order; fails at the first that fails.
    Sequence(Vec<Spec>),
    /// Children in order; succeeds at the first that succeeds.
    Fallback(Vec<Spec>),
    /// Children ticked together: succeeds once `success` of them succeeded, fails once
    /// `failure` of them failed (the others are halted).
    Parallel {
        /// Successes needed (`None`: all the children).
        success: Option<usize>,
        /// Failures that fail it.
        failure: usize,
        /// The children.
        children: Vec<Spec>,
    },
    /// The child again after a failure, up to `attempts` times in all (`None`: for ever).
    Retry {
        /// Attempts in all.
        attempts: Option<u32>,
        /// The child.
        child: Box<Spec>,
    },
    /// The child, halted and failed if it runs longer than `after` (fabric time).
    Timeout {
        /// How long the child may run.
        after: Duration,
        /// The child.
        child: Box<Spec>,
    },
    /// The child's success as failure and the other way round.
    Inverter(Box<Spec>),
    /// The child again and again while it succeeds (running meanwhile); fails when it fails.
    KeepRunningUntilFailure(Box<Spec>),
    /// The child, then success whatever it returned.
    ForceSuccess(Box<Spec>),
    /// The child, then failure whatever it returned.
    ForceFailure(Box<Spec>),
    /// A parameter set for as long as the child runs, restored after (also when halted).
    WithParam {
        /// Skill.
        skill: String,
        /// Parameter.
        param: String,
        /// Value, as `ctl set` takes it.
        value: String,
        /// The child.
        child: Box<Spec>,
    },
    /// Activate skills (all or none).
    Activate(Vec<String>),
    /// Deactivate skills (all or none).
    Deactivate(Vec<String>),
    /// Want skills (all or none): each is activated with the skills it reads from.
    Want(Vec<String>),
    /// Release wanted skills (all or none), and what was activated only for them.
    Release(Vec<String>),
    /// Set a parameter (not restored).
    SetParam {
        /// Skill.
        skill: String,
        /// Parameter.
        param: String,
        /// Value, as `ctl set` takes it.
        value: String,
    },
    /// Running until a monitor on `condition` fires (held `hold` cycles), then success.
    WaitFor {
        /// A monitor expression (`barcode_track.target.range < 1.7`).
        condition: String,
        /// Cycles it must hold.
        hold: u32,
    },
    /// Running for `after` of fabric time, then success.
    Sleep(Duration),
    /// Running until `skillfab up` gives up restarting this process (it kept crashing), then
    /// success: a plan's way to react to a part of the fabric that will not come back.
    WaitGaveUp(String),
    /// A line in the step log; success.
    Log(String),
    /// Success.
    AlwaysSuccess,
    /// Failure.
    AlwaysFailure,
    /// Another tree of the plan, by its ID.
    SubTree(String),
}

/// A name of the fabric a plan uses (checked by `skillfab sequence --check` against the
/// skills' declarations).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reference<'a> {
    /// A skill activated or deactivated.
    Skill(&'a str),
    /// A parameter set, with the value written.
    Param {
        /// Skill.
        skill: &'a str,
        /// Parameter.
        param: &'a str,
        /// Value, as `ctl set` takes it.
        value: &'a str,
    },
    /// A monitor expression (its paths name skills, outputs and fields).
    Condition(&'a str),
    /// A process of the launch file (`WaitGaveUp`).
    Process(&'a str),
}

/// Where a plan uses a name: the node and its line.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Use<'a> {
    /// The tree's ID.
    pub tree: &'a str,
    /// The node's name (its `name` attribute or element).
    pub node: &'a str,
    /// Its line.
    pub line: u32,
    /// The name used.
    pub what: Reference<'a>,
}

impl Spec {
    /// The names of the fabric this node itself uses.
    fn own_references(&self) -> Vec<Reference<'_>> {
        match &self.kind {
            Kind::Activate(skills)
            | Kind::Deactivate(skills)
            | Kind::Want(skills)
            | Kind::Release(skills) => skills.iter().map(|s| Reference::Skill(s)).collect(),
            Kind::SetParam {
                skill,
                param,
                value,
            }
            | Kind::WithParam {
                skill,
                param,
                value,
                ..
            } => vec![Reference::Param {
                skill,
                param,
                value,
            }],
            Kind::WaitFor { condition, .. } => vec![Reference::Condition(condition)],
            Kind::WaitGaveUp(process) => vec![Reference::Process(process)],
            _ => Vec::new(),
        }
    }
}

/// A whole plan: its trees by ID and the one to run.
#[derive(Debug, Clone, PartialEq)]
pub struct Plan {
    /// Trees by ID.
    pub trees: BTreeMap<String, Spec>,
    /// The tree run unless another is asked for (`main_tree_to_execute`, or the only one).
    pub main: String,
    /// A fingerprint of the file's text (FNV-1a, 64 bits): a restarted runner resumes only
    /// the plan that was running, not a file changed since.
    pub fingerprint: u64,
}

/// FNV-1a over `bytes`: stable across builds and platforms (unlike `std`'s hasher).
pub(crate) fn fnv1a(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, b| {
        (h ^ u64::from(*b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// A reader of one file's elements: errors carry the file and the element's line.
struct Reader<'a> {
    file: &'a str,
    doc: &'a roxmltree::Document<'a>,
}

impl Reader<'_> {
    fn error(&self, node: roxmltree::Node<'_, '_>, reason: String) -> PlanError {
        PlanError {
            file: self.file.to_string(),
            line: self.doc.text_pos_at(node.range().start).row,
            reason,
        }
    }

    fn attr(&self, node: roxmltree::Node<'_, '_>, name: &str) -> Result<String, PlanError> {
        node.attribute(name).map(str::to_string).ok_or_else(|| {
            self.error(
                node,
                format!(
                    "<{}> needs the attribute {name}=\"…\"",
                    node.tag_name().name()
                ),
            )
        })
    }

    /// The attribute `name` as a number; `kind` says what is expected, for the error.
    fn number<T: std::str::FromStr>(
        &self,
        node: roxmltree::Node<'_, '_>,
        name: &str,
        kind: &str,
    ) -> Result<Option<T>, PlanError> {
        node.attribute(name)
            .map(|v| {
                v.trim().parse::<T>().map_err(|_| {
                    let hint = if v.contains('{') {
                        " (there is no blackboard: write the value itself)"
                    } else {
                        ""
                    };
                    self.error(
                        node,
                        format!(
                            "<{}> {name}=\"{v}\": {kind} expected{hint}",
                            node.tag_name().name()
                        ),
                    )
                })
            })
            .transpose()
    }

    /// Refuses attributes the node does not take (a misspelt one would be ignored silently);
    /// `name` and `_…` (Groot's) go with every node.
    fn only(&self, node: roxmltree::Node<'_, '_>, takes: &[&str]) -> Result<(), PlanError> {
        for a in node.attributes() {
            let n = a.name();
            if n != "name" && !n.starts_with('_') && !takes.contains(&n) {
                let expected = if takes.is_empty() {
                    "it takes only name".to_string()
                } else {
                    format!("it takes {}", takes.join(", "))
                };
                return Err(self.error(
                    node,
                    format!(
                        "<{}> has no attribute {n} ({expected})",
                        node.tag_name().name()
                    ),
                ));
            }
        }
        Ok(())
    }

    fn msec(&self, node: roxmltree::Node<'_, '_>) -> Result<Duration, PlanError> {
        let ms: u64 = self
            .number(node, "msec", "milliseconds, a whole number")?
            .ok_or_else(|| {
                self.error(
                    node,
                    format!("<{}> needs msec=\"…\"", node.tag_name().name()),
                )
            })?;
        Ok(Duration::from_millis(ms))
    }

    fn skills(&self, node: roxmltree::Node<'_, '_>) -> Result<Vec<String>, PlanError> {
        let list: Vec<String> = self
            .attr(node, "skills")?
            .split([',', ';', ' '])
            .map(str::trim)
            .filter(|s| !s.is_empty())
            .map(str::to_string)
            .collect();
        if list.is_empty() {
            return Err(self.error(node, "skills=\"\" names no skill".into()));
        }
        Ok(list)
    }

    /// The element children of `node` (comments and text between them are skipped; other
    /// text is a mistake).
    fn children<'n>(
        &self,
        node: roxmltree::Node<'n, 'n>,
    ) -> Result<Vec<roxmltree::Node<'n, 'n>>, PlanError> {
        let mut out = Vec::new();
        for c in node.children() {
            if c.is_element() {
                out.push(c);
            } else if c.is_text() && c.text().is_some_and(|t| !t.trim().is_empty()) {
                return Err(self.error(c, "text where a node was expected".into()));
            }
        }
        Ok(out)
    }

    fn one_child(
        &self,
        node: roxmltree::Node<'_, '_>,
        depth: usize,
    ) -> Result<Box<Spec>, PlanError> {
        match self.children(node)?.as_slice() {
            [c] => Ok(Box::new(self.spec(*c, depth + 1)?)),
            other => Err(self.error(
                node,
                format!(
                    "<{}> is a decorator: it takes exactly one child, not {}",
                    node.tag_name().name(),
                    other.len()
                ),
            )),
        }
    }

    fn many(&self, node: roxmltree::Node<'_, '_>, depth: usize) -> Result<Vec<Spec>, PlanError> {
        let children = self.children(node)?;
        if children.is_empty() {
            return Err(self.error(
                node,
                format!("<{}> has no children", node.tag_name().name()),
            ));
        }
        children
            .into_iter()
            .map(|c| self.spec(c, depth + 1))
            .collect()
    }

    fn leaf(&self, node: roxmltree::Node<'_, '_>) -> Result<(), PlanError> {
        match self.children(node)?.first() {
            Some(c) => Err(self.error(
                *c,
                format!("<{}> takes no children", node.tag_name().name()),
            )),
            None => Ok(()),
        }
    }

    fn spec(&self, node: roxmltree::Node<'_, '_>, depth: usize) -> Result<Spec, PlanError> {
        if depth > MAX_DEPTH {
            return Err(self.error(node, format!("nodes nested deeper than {MAX_DEPTH}")));
        }
        let tag = node.tag_name().name();
        // BehaviorTree.CPP's generic forms: <Action ID="Activate" …/>, <Condition ID=…/>.
        let generic = matches!(tag, "Action" | "Condition" | "Control" | "Decorator");
        let kind_name = if generic {
            node.attribute("ID")
                .ok_or_else(|| self.error(node, format!("<{tag}> needs ID=\"…\"")))?
        } else {
            tag
        };
        // The attributes each node takes (the generic forms' ID besides).
        let takes: &[&str] = match kind_name {
            "Parallel" => &["success_count", "failure_count"],
            "RetryUntilSuccessful" => &["num_attempts"],
            "Timeout" | "Sleep" => &["msec"],
            "WithParam" | "SetParam" => &["skill", "param", "value"],
            "Activate" | "Deactivate" | "Want" | "Release" => &["skills"],
            "WaitFor" => &["condition", "hold"],
            "Log" => &["message"],
            "WaitGaveUp" => &["process"],
            "SubTree" => &["ID"],
            _ => &[],
        };
        let mut takes = takes.to_vec();
        if generic {
            takes.push("ID");
        }
        let kind = match kind_name {
            "Sequence" => Kind::Sequence(self.many(node, depth)?),
            "Fallback" => Kind::Fallback(self.many(node, depth)?),
            "Parallel" => {
                let children = self.many(node, depth)?;
                let count_kind = "-1 (all) or a number of children";
                let success: i64 = self
                    .number(node, "success_count", count_kind)?
                    .unwrap_or(-1);
                let failure: i64 = self.number(node, "failure_count", count_kind)?.unwrap_or(1);
                let n = children.len() as i64;
                let count = |v: i64, what: &str| match v {
                    -1 => Ok(None),
                    v if (1..=n).contains(&v) => Ok(Some(v as usize)),
                    v => Err(self.error(
                        node,
                        format!("{what}=\"{v}\": -1 (all) or 1 to {n} (its children)"),
                    )),
                };
                Kind::Parallel {
                    success: count(success, "success_count")?,
                    failure: count(failure, "failure_count")?.unwrap_or(children.len()),
                    children,
                }
            }
            "RetryUntilSuccessful" => {
                let n: i64 = self
                    .number(node, "num_attempts", "-1 (for ever) or at least 1")?
                    .ok_or_else(|| {
                        self.error(
                            node,
                            "<RetryUntilSuccessful> needs num_attempts=\"…\" (-1: for ever)".into(),
                        )
                    })?;
                let attempts = match n {
                    -1 => None,
                    n if n >= 1 => Some(u32::try_from(n).map_err(|_| {
                        self.error(node, format!("num_attempts=\"{n}\": at most {}", u32::MAX))
                    })?),
                    n => {
                        return Err(
                            self.error(node, format!("num_attempts=\"{n}\": -1 or at least 1"))
                        );
                    }
                };
                Kind::Retry {
                    attempts,
                    child: self.one_child(node, depth)?,
                }
            }
            "Timeout" => {
                let after = self.msec(node)?;
                if after.is_zero() {
                    return Err(self.error(
                        node,
                        "<Timeout> msec=\"0\": at least 1 (to wait without a limit, leave \
                         the Timeout out)"
                            .into(),
                    ));
                }
                Kind::Timeout {
                    after,
                    child: self.one_child(node, depth)?,
                }
            }
            "Inverter" => Kind::Inverter(self.one_child(node, depth)?),
            "KeepRunningUntilFailure" => {
                Kind::KeepRunningUntilFailure(self.one_child(node, depth)?)
            }
            "ForceSuccess" => Kind::ForceSuccess(self.one_child(node, depth)?),
            "ForceFailure" => Kind::ForceFailure(self.one_child(node, depth)?),
            "WithParam" => Kind::WithParam {
                skill: self.attr(node, "skill")?,
                param: self.attr(node, "param")?,
                value: self.attr(node, "value")?,
                child: self.one_child(node, depth)?,
            },
            "Activate" => {
                self.leaf(node)?;
                Kind::Activate(self.skills(node)?)
            }
            "Deactivate" => {
                self.leaf(node)?;
                Kind::Deactivate(self.skills(node)?)
            }
            "Want" => {
                self.leaf(node)?;
                Kind::Want(self.skills(node)?)
            }
            "Release" => {
                self.leaf(node)?;
                Kind::Release(self.skills(node)?)
            }
            "SetParam" => {
                self.leaf(node)?;
                Kind::SetParam {
                    skill: self.attr(node, "skill")?,
                    param: self.attr(node, "param")?,
                    value: self.attr(node, "value")?,
                }
            }
            "WaitFor" => {
                self.leaf(node)?;
                Kind::WaitFor {
                    condition: self.attr(node, "condition")?,
                    hold: self
                        .number(node, "hold", "cycles, a whole number")?
                        .unwrap_or(0),
                }
            }
            "Sleep" => {
                self.leaf(node)?;
                Kind::Sleep(self.msec(node)?)
            }
            "Log" => {
                self.leaf(node)?;
                Kind::Log(self.attr(node, "message")?)
            }
            "WaitGaveUp" => {
                self.leaf(node)?;
                Kind::WaitGaveUp(self.attr(node, "process")?)
            }
            "AlwaysSuccess" => {
                self.leaf(node)?;
                Kind::AlwaysSuccess
            }
            "AlwaysFailure" => {
                self.leaf(node)?;
                Kind::AlwaysFailure
            }
            "SubTree" => {
                self.leaf(node)?;
                Kind::SubTree(self.attr(node, "ID")?)
            }
            other => {
                return Err(self.error(
                    node,
                    format!(
                        "unknown node <{other}> (control: Sequence, Fallback, Parallel; \
                         decorators: RetryUntilSuccessful, Timeout, Inverter, ForceSuccess, \
                         ForceFailure, KeepRunningUntilFailure, WithParam; actions: Activate, \
                         Deactivate, Want, Release, SetParam, WaitFor, WaitGaveUp, Sleep, Log, \
                         AlwaysSuccess, AlwaysFailure, SubTree)"
                    ),
                ));
            }
        };
        self.only(node, &takes)?;
        Ok(Spec {
            kind,
            name: node
                .attribute("name")
                .map_or_else(|| kind_name.to_string(), str::to_string),
            line: self.doc.text_pos_at(node.range().start).row,
        })
    }
}

impl Plan {
    /// Every name of the fabric the plan uses, tree by tree in the order written.
    pub fn uses(&self) -> Vec<Use<'_>> {
        let mut out = Vec::new();
        for (tree, root) in &self.trees {
            let mut stack = vec![root];
            while let Some(node) = stack.pop() {
                out.extend(node.own_references().into_iter().map(|what| Use {
                    tree,
                    node: &node.name,
                    line: node.line,
                    what,
                }));
                stack.extend(node.kind.children().into_iter().rev());
            }
        }
        out
    }

    /// Reads a plan from `text`; `file` names it in errors.
    pub fn parse(text: &str, file: &str) -> Result<Plan, PlanError> {
        let doc = roxmltree::Document::parse(text).map_err(|e| PlanError {
            file: file.to_string(),
            line: e.pos().row,
            reason: format!("not well-formed XML: {e}"),
        })?;
        let r = Reader { file, doc: &doc };
        let root = doc.root_element();
        if root.tag_name().name() != "root" {
            return Err(r.error(
                root,
                "the document element must be <root BTCPP_format=\"4\">".into(),
            ));
        }
        if let Some(v) = root.attribute("BTCPP_format")
            && v != "4"
        {
            return Err(r.error(root, format!("BTCPP_format=\"{v}\": only format 4 is read")));
        }
        let mut trees = BTreeMap::new();
        for t in r.children(root)? {
            match t.tag_name().name() {
                "BehaviorTree" => {
                    let id = r.attr(t, "ID")?;
                    let body = match r.children(t)?.as_slice() {
                        [b] => r.spec(*b, 0)?,
                        other => {
                            return Err(r.error(
                                t,
                                format!(
                                    "tree '{id}' must have exactly one root node, not {}",
                                    other.len()
                                ),
                            ));
                        }
                    };
                    if trees.insert(id.clone(), body).is_some() {
                        return Err(r.error(t, format!("a second tree with ID '{id}'")));
                    }
                }
                // Groot's palette of node types: not needed to run.
                "TreeNodesModel" => {}
                other => {
                    return Err(r.error(
                        t,
                        format!("<{other}> in <root>: only <BehaviorTree> and <TreeNodesModel>"),
                    ));
                }
            }
        }
        let main = match root.attribute("main_tree_to_execute") {
            Some(m) => m.to_string(),
            None if trees.len() == 1 => trees.keys().next().cloned().unwrap_or_default(),
            None => {
                return Err(r.error(
                    root,
                    "several trees and no main_tree_to_execute=\"…\" to say which to run".into(),
                ));
            }
        };
        let plan = Plan {
            trees,
            main,
            fingerprint: fnv1a(text.as_bytes()),
        };
        if !plan.trees.contains_key(&plan.main) {
            return Err(r.error(
                root,
                format!(
                    "main_tree_to_execute=\"{}\": no tree has that ID",
                    plan.main
                ),
            ));
        }
        plan.check_subtrees(file)?;
        Ok(plan)
    }

    /// Every `SubTree` names a tree, no tree contains itself, and no tree is larger than
    /// [`MAX_NODES`] with its sub-trees inlined (each tree is walked once).
    fn check_subtrees(&self, file: &str) -> Result<(), PlanError> {
        /// Nodes of `spec` with its sub-trees inlined.
        fn size(
            plan: &Plan,
            spec: &Spec,
            path: &mut Vec<String>,
            sizes: &mut BTreeMap<String, usize>,
            file: &str,
        ) -> Result<usize, PlanError> {
            let err = |reason: String| PlanError {
                file: file.to_string(),
                line: spec.line,
                reason,
            };
            let n = match &spec.kind {
                Kind::SubTree(id) => {
                    if path.contains(id) {
                        return Err(err(format!(
                            "SubTree '{id}' contains itself ({} → {id})",
                            path.join(" → ")
                        )));
                    }
                    if let Some(n) = sizes.get(id) {
                        return Ok(*n);
                    }
                    let Some(tree) = plan.trees.get(id) else {
                        return Err(err(format!("SubTree ID=\"{id}\": no tree has that ID")));
                    };
                    path.push(id.clone());
                    let n = size(plan, tree, path, sizes, file)?;
                    path.pop();
                    sizes.insert(id.clone(), n);
                    n
                }
                other => {
                    let mut n = 1usize;
                    for c in other.children() {
                        n = n.saturating_add(size(plan, c, path, sizes, file)?);
                    }
                    n
                }
            };
            if n > MAX_NODES {
                return Err(err(format!(
                    "more than {MAX_NODES} nodes with its sub-trees inlined"
                )));
            }
            Ok(n)
        }
        let mut sizes = BTreeMap::new();
        for (id, tree) in &self.trees {
            size(self, tree, &mut vec![id.clone()], &mut sizes, file)?;
        }
        Ok(())
    }
}

impl Kind {
    /// The child nodes as written.
    pub fn children(&self) -> Vec<&Spec> {
        match self {
            Kind::Sequence(c) | Kind::Fallback(c) | Kind::Parallel { children: c, .. } => {
                c.iter().collect()
            }
            Kind::Retry { child, .. }
            | Kind::Timeout { child, .. }
            | Kind::WithParam { child, .. }
            | Kind::Inverter(child)
            | Kind::KeepRunningUntilFailure(child)
            | Kind::ForceSuccess(child)
            | Kind::ForceFailure(child) => vec![child],
            _ => Vec::new(),
        }
    }
}

/// The longest [`Kind::detail`] (characters): a node's detail travels in the plan's tree
/// to the manager, whose requests are bounded.
const MAX_DETAIL: usize = 200;

impl Kind {
    /// Its BehaviorTree.CPP tag, as a plan is written (a sub-tree is shown as the tree it
    /// names, so `SubTree` is never a node of a running tree).
    pub fn tag(&self) -> &'static str {
        match self {
            Kind::Sequence(_) => "Sequence",
            Kind::Fallback(_) => "Fallback",
            Kind::Parallel { .. } => "Parallel",
            Kind::Retry { .. } => "RetryUntilSuccessful",
            Kind::Timeout { .. } => "Timeout",
            Kind::Inverter(_) => "Inverter",
            Kind::KeepRunningUntilFailure(_) => "KeepRunningUntilFailure",
            Kind::ForceSuccess(_) => "ForceSuccess",
            Kind::ForceFailure(_) => "ForceFailure",
            Kind::WithParam { .. } => "WithParam",
            Kind::Activate(_) => "Activate",
            Kind::Deactivate(_) => "Deactivate",
            Kind::Want(_) => "Want",
            Kind::Release(_) => "Release",
            Kind::SetParam { .. } => "SetParam",
            Kind::WaitFor { .. } => "WaitFor",
            Kind::Sleep(_) => "Sleep",
            Kind::WaitGaveUp(_) => "WaitGaveUp",
            Kind::Log(_) => "Log",
            Kind::AlwaysSuccess => "AlwaysSuccess",
            Kind::AlwaysFailure => "AlwaysFailure",
            Kind::SubTree(_) => "SubTree",
        }
    }

    /// What the node does, in short (its attributes as they matter to a reader of the live
    /// tree), at most 200 characters; empty when there is nothing to say.
    pub fn detail(&self) -> String {
        let ms = |d: &Duration| format!("{} ms", d.as_millis());
        let text = match self {
            Kind::Parallel {
                success, failure, ..
            } => match success {
                Some(s) => format!("success {s}, failure {failure}"),
                None => format!("success all, failure {failure}"),
            },
            Kind::Retry { attempts, .. } => match attempts {
                Some(n) => format!("{n} attempts"),
                None => "for ever".to_string(),
            },
            Kind::Timeout { after, .. } => ms(after),
            Kind::Sleep(d) => ms(d),
            Kind::WithParam {
                skill,
                param,
                value,
                ..
            }
            | Kind::SetParam {
                skill,
                param,
                value,
            } => format!("{skill}.{param} = {value}"),
            Kind::Activate(s) | Kind::Deactivate(s) | Kind::Want(s) | Kind::Release(s) => {
                s.join(", ")
            }
            Kind::WaitFor { condition, hold } if *hold > 0 => {
                format!("{condition} (held {hold} cycles)")
            }
            Kind::WaitFor { condition, .. } => condition.clone(),
            Kind::WaitGaveUp(p) => p.clone(),
            Kind::Log(m) => m.clone(),
            Kind::SubTree(id) => id.clone(),
            Kind::Sequence(_)
            | Kind::Fallback(_)
            | Kind::Inverter(_)
            | Kind::KeepRunningUntilFailure(_)
            | Kind::ForceSuccess(_)
            | Kind::ForceFailure(_)
            | Kind::AlwaysSuccess
            | Kind::AlwaysFailure => String::new(),
        };
        match text.char_indices().nth(MAX_DETAIL) {
            Some((cut, _)) => format!("{}…", &text[..cut]),
            None => text,
        }
    }
}
