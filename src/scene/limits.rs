//! Size limits checked *before* anything proportional to user input is allocated: elements
//! per scene, members per sweep, and a memory estimate (members × elements × bytes per
//! element) against a limit the user can raise with the `COSSERAT_MAX_MEMORY` environment
//! variable (`docs/guarantees.md`).

/// Most elements in one scene (all rods together), and in one segment.
pub const MAX_SCENE_ELEMENTS: usize = 1_000_000;

/// Most time steps of one run (`t_end / dt`).
pub const MAX_STEPS: f64 = 1e9;

/// Most members in one sweep (or rods in one bench batch).
pub const MAX_MEMBERS: u64 = 10_000_000;

/// Memory a running member needs per element, in bytes (element data, state, the block
/// sparse tangent and its factorization, records): the peak RSS of `cosserat run` on the
/// cantilever with 10⁵ elements less that with 10³, per element, measured 11.7 kB.
pub const BYTES_PER_ELEMENT: u64 = 12_000;

/// Memory a member needs besides its elements (its scene, solver set-up, records).
pub const BYTES_PER_MEMBER: u64 = 200_000;

/// Memory of a queued member's description (its model and parameters) per element, and
/// besides its elements: `bench --rods 100000 --elements 10` held 459 MB of member
/// descriptions (4.6 kB per member) before running.
pub const DESCRIPTION_BYTES_PER_ELEMENT: u64 = 400;

/// See [`DESCRIPTION_BYTES_PER_ELEMENT`].
pub const DESCRIPTION_BYTES_PER_MEMBER: u64 = 1_000;

/// Most members of a batch running at once: the GPU path's default slots
/// (`crate::batch::DEFAULT_GPU_SLOTS`); the CPU path runs one per thread. Measured peak
/// RSS of `bench --rods 100000 --elements 10 --steps 2`: 0.46 GB on the CPU path, 1.9 GB on
/// the GPU path (4096 slots); this estimate gives 1.8 GB.
pub const MAX_IN_FLIGHT: u64 = 4096;

/// Default memory limit when `COSSERAT_MAX_MEMORY` is not set: 16 GiB, or less where the
/// process may not have that much (see [`system_memory_bound`]).
pub const DEFAULT_MAX_MEMORY: u64 = 16 << 30;

/// Most contact spheres in one scene (all `[[contact]]` sections together): a contact chain
/// has one sphere per contact radius along its rods, so a tiny radius is a huge chain.
pub const MAX_CONTACT_SPHERES: u64 = 1_000_000;

/// Most contact spheres within one contact diameter along a rod (`2ρ / spacing`, spacing
/// = the element length where it is below ρ): the pair search checks each sphere against
/// those within its reach at every Newton iteration, so this bounds the work per sphere.
pub const MAX_SPHERES_PER_DIAMETER: f64 = 1000.0;

/// Memory a running member needs per contact sphere (its sample point, its position, the
/// pair-search grid entry and its share of the pair lists): the peak RSS of `cosserat check`
/// on the self-contacting plectoneme with 100 001 spheres less that with 10 001, per
/// sphere, measured 0.31 kB.
pub const BYTES_PER_CONTACT_SPHERE: u64 = 400;

/// Memory of a queued member's description per contact sphere (its sample point).
pub const DESCRIPTION_BYTES_PER_CONTACT_SPHERE: u64 = 48;

/// Memory of one node in one `trajectory.npz` frame held until the run ends (position,
/// velocity, three directors: 15 f64, rounded up).
pub const BYTES_PER_TRAJECTORY_NODE: u64 = 128;

/// Memory of one node in one snapshot or animation frame held until the run ends.
pub const BYTES_PER_SNAPSHOT_NODE: u64 = 32;

/// Memory of one step record (`StepRecord`, asserted at most this by a unit test of
/// `observe::record`).
pub const BYTES_PER_RECORD: u64 = 512;

/// What one member (one run) holds in memory, in the units the estimate counts.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Footprint {
    /// Elements (all rods).
    pub elements: u64,
    /// Nodes.
    pub nodes: u64,
    /// Contact spheres (all `[[contact]]` chains).
    pub contact_spheres: u64,
    /// `trajectory.npz` frames held until the run ends.
    pub trajectory_frames: u64,
    /// Snapshot and animation frames held until the run ends.
    pub snapshot_frames: u64,
    /// Step records held until the run ends (chart records, a batch member's history).
    pub records: u64,
    /// Bytes of results a member keeps after it has finished, until its whole batch ends
    /// (a study's samples, a batch member's history).
    pub kept_bytes: u64,
}

impl Footprint {
    /// A member of `elements` elements and nothing else (nodes counted as elements + 1).
    pub fn elements(elements: u64) -> Self {
        Self {
            elements,
            nodes: elements.saturating_add(1),
            ..Self::default()
        }
    }

    /// The footprint of running `model` (no output frames).
    pub fn of_model(model: &crate::model::Model) -> Self {
        Self {
            elements: model.elements.len() as u64,
            nodes: model.nodes.len() as u64,
            contact_spheres: model
                .rod_contacts
                .iter()
                .map(|c| c.points.len() as u64)
                .sum(),
            ..Self::default()
        }
    }

    /// Bytes while it runs (saturating): solver and state per element, contact per sphere,
    /// frames held for the outputs, and the fixed share of a member.
    pub fn running_bytes(&self) -> u64 {
        let frames = self
            .trajectory_frames
            .saturating_mul(BYTES_PER_TRAJECTORY_NODE)
            .saturating_add(self.snapshot_frames.saturating_mul(BYTES_PER_SNAPSHOT_NODE))
            .saturating_mul(self.nodes);
        self.elements
            .saturating_mul(BYTES_PER_ELEMENT)
            .saturating_add(
                self.contact_spheres
                    .saturating_mul(BYTES_PER_CONTACT_SPHERE),
            )
            .saturating_add(frames)
            .saturating_add(self.records.saturating_mul(BYTES_PER_RECORD))
            .saturating_add(BYTES_PER_MEMBER)
    }

    /// Bytes of its description while it waits in a batch (saturating).
    pub fn description_bytes(&self) -> u64 {
        self.elements
            .saturating_mul(DESCRIPTION_BYTES_PER_ELEMENT)
            .saturating_add(
                self.contact_spheres
                    .saturating_mul(DESCRIPTION_BYTES_PER_CONTACT_SPHERE),
            )
            .saturating_add(self.kept_bytes)
            .saturating_add(DESCRIPTION_BYTES_PER_MEMBER)
    }

    /// The parts of [`Self::running_bytes`] as `(what, bytes)`, largest first (for errors).
    pub fn parts(&self) -> Vec<(String, u64)> {
        let mut v = vec![
            (
                format!("{} element(s)", self.elements),
                self.elements.saturating_mul(BYTES_PER_ELEMENT),
            ),
            (
                format!("{} contact sphere(s)", self.contact_spheres),
                self.contact_spheres
                    .saturating_mul(BYTES_PER_CONTACT_SPHERE),
            ),
            (
                format!(
                    "{} trajectory frame(s) of {} node(s)",
                    self.trajectory_frames, self.nodes
                ),
                self.trajectory_frames
                    .saturating_mul(BYTES_PER_TRAJECTORY_NODE)
                    .saturating_mul(self.nodes),
            ),
            (
                format!(
                    "{} snapshot frame(s) of {} node(s)",
                    self.snapshot_frames, self.nodes
                ),
                self.snapshot_frames
                    .saturating_mul(BYTES_PER_SNAPSHOT_NODE)
                    .saturating_mul(self.nodes),
            ),
            (
                format!("{} step record(s)", self.records),
                self.records.saturating_mul(BYTES_PER_RECORD),
            ),
            ("results kept".into(), self.kept_bytes),
        ];
        v.retain(|(_, b)| *b > 0);
        v.sort_by_key(|p| std::cmp::Reverse(p.1));
        v
    }
}

/// The environment variable that overrides [`DEFAULT_MAX_MEMORY`] (bytes, or with a
/// `K`, `M`, `G` or `T` suffix, powers of 1024: `COSSERAT_MAX_MEMORY=64G`).
pub const MEMORY_ENV: &str = "COSSERAT_MAX_MEMORY";

/// A size refused before allocation.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum LimitError {
    /// The estimate exceeds the memory limit.
    #[error(
        "{what} would need about {} of memory ({members} member(s); per member: {}), above the limit of {} ({}; set {MEMORY_ENV}, e.g. {MEMORY_ENV}=64G, to raise it)",
        human(*.bytes), describe_parts(.parts), human(*.limit), .source_of_limit
    )]
    Memory {
        /// What was being sized.
        what: String,
        /// Members (or rods).
        members: u64,
        /// Elements per member.
        elements: u64,
        /// What a member holds, largest first: `(what, bytes)`.
        parts: Vec<(String, u64)>,
        /// Estimated bytes.
        bytes: u64,
        /// The limit in force.
        limit: u64,
        /// Where the limit comes from (the variable, the default, a process limit).
        source_of_limit: String,
    },
    /// Too many contact spheres, or too many within one contact diameter.
    #[error("{0}")]
    Contact(String),
    /// `COSSERAT_MAX_MEMORY` cannot be read.
    #[error("{MEMORY_ENV}: cannot read `{0}` as a size (expected bytes or a number with K, M, G or T, e.g. 64G)")]
    BadEnv(String),
}

/// Bytes as `12.3 GiB`.
pub fn human(b: u64) -> String {
    let units = ["B", "KiB", "MiB", "GiB", "TiB", "PiB", "EiB"];
    let mut x = b as f64;
    let mut u = 0;
    while x >= 1024.0 && u + 1 < units.len() {
        x /= 1024.0;
        u += 1;
    }
    if u == 0 {
        format!("{b} B")
    } else {
        format!("{x:.1} {}", units[u])
    }
}

/// Parses a size: plain bytes or a number with a `K`, `M`, `G`, `T` suffix (optionally
/// followed by `B` or `iB`), powers of 1024.
pub fn parse_size(s: &str) -> Option<u64> {
    let t = s.trim();
    let t = t
        .strip_suffix("iB")
        .or_else(|| t.strip_suffix('B'))
        .unwrap_or(t);
    let (num, mult) = match t.chars().last()? {
        'k' | 'K' => (&t[..t.len() - 1], 1u64 << 10),
        'm' | 'M' => (&t[..t.len() - 1], 1 << 20),
        'g' | 'G' => (&t[..t.len() - 1], 1 << 30),
        't' | 'T' => (&t[..t.len() - 1], 1 << 40),
        _ => (t, 1),
    };
    let x: f64 = num.trim().parse().ok()?;
    if !(x.is_finite() && x > 0.0) {
        return None;
    }
    let b = x * mult as f64;
    (b < u64::MAX as f64).then_some(b as u64)
}

fn describe_parts(parts: &[(String, u64)]) -> String {
    if parts.is_empty() {
        return "its fixed share".into();
    }
    parts
        .iter()
        .map(|(w, b)| format!("{w} ≈ {}", human(*b)))
        .collect::<Vec<_>>()
        .join(", ")
}

/// What the process may hold at most, where the system says so: half the address-space
/// and data-segment limits (`ulimit -v`, `ulimit -d`: virtual memory runs ahead of the
/// resident set), the cgroup's `memory.max` (containers, Slurm jobs) and the machine's
/// physical memory, less a tenth each for the rest of the system. `None` where none is
/// known.
pub fn system_memory_bound() -> Option<(u64, String)> {
    let mut best: Option<(u64, String)> = None;
    let mut take = |bytes: u64, why: String| {
        if best.as_ref().is_none_or(|(b, _)| bytes < *b) {
            best = Some((bytes, why));
        }
    };
    #[cfg(unix)]
    {
        for (res, name) in [
            (libc::RLIMIT_AS, "the address-space limit (ulimit -v)"),
            (libc::RLIMIT_DATA, "the data-segment limit (ulimit -d)"),
        ] {
            let mut r = libc::rlimit {
                rlim_cur: 0,
                rlim_max: 0,
            };
            // SAFETY: getrlimit only writes the struct it is given.
            if unsafe { libc::getrlimit(res, &mut r) } == 0 && r.rlim_cur != libc::RLIM_INFINITY {
                // rlim_t is u64 on Linux, not on every Unix.
                #[allow(clippy::unnecessary_cast)]
                let cur = r.rlim_cur as u64;
                take(cur / 2, format!("half of {name} {}", human(cur)));
            }
        }
        // SAFETY: sysconf has no preconditions.
        let (pages, page) = unsafe {
            (
                libc::sysconf(libc::_SC_PHYS_PAGES),
                libc::sysconf(libc::_SC_PAGESIZE),
            )
        };
        if pages > 0 && page > 0 {
            let phys = (pages as u64).saturating_mul(page as u64);
            take(
                phys / 10 * 9,
                format!("90 % of the physical memory {}", human(phys)),
            );
        }
    }
    for f in [
        "/sys/fs/cgroup/memory.max",
        "/sys/fs/cgroup/memory/memory.limit_in_bytes",
    ] {
        if let Some(v) = std::fs::read_to_string(f)
            .ok()
            .and_then(|s| s.trim().parse::<u64>().ok())
        {
            take(v / 10 * 9, format!("90 % of the cgroup limit {}", human(v)));
        }
    }
    best
}

/// The memory limit in force and where it comes from: `COSSERAT_MAX_MEMORY` if set, else
/// the smaller of [`DEFAULT_MAX_MEMORY`] and [`system_memory_bound`].
pub fn memory_limit_with_source() -> Result<(u64, String), LimitError> {
    match std::env::var(MEMORY_ENV) {
        Ok(v) => parse_size(&v)
            .map(|b| (b, format!("{MEMORY_ENV}={v}")))
            .ok_or(LimitError::BadEnv(v)),
        Err(_) => Ok(match system_memory_bound() {
            Some((b, why)) if b < DEFAULT_MAX_MEMORY => (b, format!("the default: {why}")),
            _ => (DEFAULT_MAX_MEMORY, "the default".into()),
        }),
    }
}

/// The memory limit in force (see [`memory_limit_with_source`]).
pub fn memory_limit() -> Result<u64, LimitError> {
    memory_limit_with_source().map(|(b, _)| b)
}

/// Estimated bytes of a batch of `members` members of `elements` elements each
/// (saturating): every member's description is held for the whole batch, but at most
/// [`MAX_IN_FLIGHT`] members run at once (the batches stream members through their slots).
pub fn estimate(members: u64, elements: u64) -> u64 {
    estimate_batch(members, &Footprint::elements(elements))
}

/// Estimated bytes of a batch of `members` members, each holding `member` (saturating);
/// one member is one run.
pub fn estimate_batch(members: u64, member: &Footprint) -> u64 {
    let described = members.saturating_mul(member.description_bytes());
    let running = members
        .min(MAX_IN_FLIGHT)
        .saturating_mul(member.running_bytes());
    described.saturating_add(running)
}

/// Refuses `members` × `elements` when its estimate exceeds the limit in force.
pub fn check_memory(what: &str, members: u64, elements: u64) -> Result<(), LimitError> {
    check_batch(what, members, &Footprint::elements(elements))
}

/// Refuses a batch of `members` members, each holding `member`, when its estimate exceeds
/// the limit in force; one run is a batch of one. Every command sizes its work here
/// before allocating it.
pub fn check_batch(what: &str, members: u64, member: &Footprint) -> Result<(), LimitError> {
    let (limit, source_of_limit) = memory_limit_with_source()?;
    let bytes = estimate_batch(members, member);
    if bytes > limit {
        return Err(LimitError::Memory {
            what: what.to_string(),
            members,
            elements: member.elements,
            parts: member.parts(),
            bytes,
            limit,
            source_of_limit,
        });
    }
    Ok(())
}

/// Refuses a contact chain of `spheres` spheres (a count computed in f64 before
/// allocating, so an overflow is `inf`) or with `per_diameter` spheres within one contact
/// diameter along a rod. `key` names what sets the count.
pub fn check_contact_spheres(spheres: f64, per_diameter: f64) -> Result<(), LimitError> {
    if spheres.is_nan() || spheres > MAX_CONTACT_SPHERES as f64 {
        return Err(LimitError::Contact(format!(
            "the contact chains would have {} spheres (one per contact radius along the rods), above the limit of {MAX_CONTACT_SPHERES}: give a larger contact radius",
            short_count(spheres)
        )));
    }
    if per_diameter.is_nan() || per_diameter > MAX_SPHERES_PER_DIAMETER {
        return Err(LimitError::Contact(format!(
            "{} contact spheres lie within one contact diameter along a rod (the contact radius is {} element lengths), above the limit of {MAX_SPHERES_PER_DIAMETER}: give a smaller contact radius or longer elements",
            short_count(per_diameter),
            short_count(per_diameter / 2.0)
        )));
    }
    Ok(())
}

/// A count for messages: exact below 10¹⁵, else `1.2e20`, `inf`.
fn short_count(x: f64) -> String {
    if x.is_finite() && x < 1e15 {
        format!("{}", x.round())
    } else {
        format!("{x:.1e}")
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sizes_parse_with_binary_suffixes_and_reject_nonsense() {
        assert_eq!(parse_size("1024"), Some(1024));
        assert_eq!(parse_size("64G"), Some(64 << 30));
        assert_eq!(parse_size("1.5KiB"), Some(1536));
        assert_eq!(parse_size("2MB"), Some(2 << 20));
        for bad in ["", "G", "-1G", "NaNG", "1e300T", "x"] {
            assert_eq!(parse_size(bad), None, "{bad}");
        }
    }

    #[test]
    fn estimate_saturates_and_the_error_names_the_override() {
        assert_eq!(estimate(u64::MAX, u64::MAX), u64::MAX);
        let e = LimitError::Memory {
            what: "sweep".into(),
            members: 10,
            elements: 5,
            parts: Footprint::elements(5).parts(),
            bytes: 3 << 30,
            limit: 1 << 30,
            source_of_limit: "the default".into(),
        }
        .to_string();
        assert!(
            e.contains("3.0 GiB") && e.contains("COSSERAT_MAX_MEMORY"),
            "{e}"
        );
    }
}
