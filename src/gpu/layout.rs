//! Struct-of-arrays layout of the kernel buffers: field `f` of element `i` lives at
//! `f * capacity + i`. Twin of the `E_*`, `S_*`, `I_*`, `O_*`, `T_*` constants at the top of
//! `shaders/element.wgsl` (which point back here); `tests/gpu_kernel.rs` checks them
//! against the shader text.

/// Element constants: `h`.
pub const E_H: usize = 0;
/// `Aρ`.
pub const E_ARHO: usize = 1;
/// `Iρ` (4, row-major).
pub const E_IRHO: usize = 2;
/// Diagonal of `C_Γ` (3).
pub const E_CG: usize = 6;
/// `C_Ω` (9, row-major).
pub const E_CO: usize = 9;
/// Reference strains (6).
pub const E_EPS0: usize = 18;
/// Rotation-free flags of the two ends (2; 1 = free).
pub const E_ROTFREE: usize = 24;
/// Time step.
pub const E_DT: usize = 26;
/// Translational dissipation rows on (1) or off (0).
pub const E_TRANS: usize = 27;
/// Scheme: 0 EM, 1 EDMC-1, 2 EDMC-2.
pub const E_SCHEME: usize = 28;
/// The scheme's four constants.
pub const E_SP: usize = 29;
/// Director dissipation on (1) or off (0).
pub const E_DIRDISS: usize = 33;
/// Kelvin–Voigt retardation time η (material damping: `2η/Δt` adds to both β).
pub const E_DAMP: usize = 34;
/// Drag per unit length `c` (the force `−c (r_{n+1} − r_n)/Δt` per length; twin of
/// `element::drag`).
pub const E_DRAG: usize = 35;
/// Point masses carried by the two ends (2; a node's point mass on one end of one of its
/// elements: twin of `element::point_mass`).
pub const E_PMASS: usize = 36;
/// Follower line loads on the element (6): force and moment per unit length in its
/// director frame, their time tables' factors at the step's middle included (twin of
/// `element::follower`).
pub const E_FOLLOW: usize = 38;
/// Number of element-constant fields.
pub const NE: usize = 44;

/// State: end positions (6).
pub const S_R: usize = 0;
/// Triads (18: end `l`, column `i`, component `c` at `9l + 3i + c`).
pub const S_D: usize = 6;
/// End velocities (6).
pub const S_V: usize = 24;
/// Director velocities (12: `[l][α]` component `c` at `6l + 3α + c`).
pub const S_VD: usize = 30;
/// Raw strains at `n` (6).
pub const S_EPS: usize = 42;
/// Number of state fields.
pub const NS: usize = 48;

/// Iteration data: element-local increment (18).
pub const I_X: usize = 0;
/// Frozen scalars `β_Γ, β_Ω, c_v, c_ν` (4).
pub const I_S: usize = 18;
/// Active flag (0 = skip, 1 = evaluate with the frozen scalars, 2 = with the consistent
/// ones, 3 = freeze the consistent ones at this iterate, then as 1: the polish round of a
/// step on the device).
pub const I_ACTIVE: usize = 22;
/// Number of iteration fields.
pub const NI: usize = 23;

/// Output: residual (18).
pub const O_R: usize = 0;
/// Row scales (18).
pub const O_SC: usize = 18;
/// Tangent (324, row-major).
pub const O_K: usize = 36;
/// Scalars used (4).
pub const O_S: usize = 360;
/// Number of output fields.
pub const NO: usize = 364;

/// Residual pass → tangent pass (intermediate buffer): new configuration (24: `r0 r1`,
/// columns of `d0`, columns of `d1`).
pub const T_C1: usize = 0;
/// Columns of `(I − ½ hat θ_l)⁻¹`, `l = 0, 1` (18).
pub const T_A: usize = 24;
/// Stresses `S*` (6).
pub const T_SS: usize = 42;
/// Director forces `f[2..8]` (stress and inertia, 18).
pub const T_F: usize = 48;
/// Tangent prep → tangent blocks: `B̃_½` columns of nodes 0 and 1 (72, at
/// `36 n + 6 k + 3 g + c` for row `k`, group `g` (u, θ), component `c`).
pub const T_BT: usize = 66;
/// `D B̃_{n+1}` columns of nodes 0 and 1 (72, same order).
pub const T_DB: usize = 138;
/// Advance pass → record pass: per element slot its terms of the invariants at `n+1` and
/// its dissipation ([`N_ADV`]: kinetic, stored energy, `L` (3), `J` (3), dissipation, the
/// sums of the translational and rotational acceleration norms' squares, how far the
/// cosine of its end triads' turn lies below the limit's, and its follower loads' work; the first [`NS`] fields hold its
/// state at `n+1`, in the state buffer's layout).
pub const T_ADV: usize = 48;
/// Fields of [`T_ADV`] and [`T_REC`].
pub const N_ADV: usize = 13;
/// Record pass: per member slot (index = member slot) the sums of [`T_ADV`] over its
/// element slots ([`N_ADV`], same order).
pub const T_REC: usize = 61;
/// Advance pass → state hand-back: per element slot of a dissipative scheme's member, the
/// frozen scalars its next step starts from (4; the consistent scalars of the accepted
/// increment), kept for a hand-back of that step to the host (a step on the device
/// overwrites [`I_S`] with its polish round's).
pub const T_FS: usize = 210;
/// Number of intermediate fields.
pub const NT: usize = 214;

/// Node-local unknowns (`u0..2 θ0..2 g0..2`) of the assembled system.
pub const A_NODE: usize = 9;
/// Entries of one 9×9 block (row-major).
pub const A_BLOCK: usize = A_NODE * A_NODE;

/// Layout of the assembled buffer written by `shaders/assemble.wgsl`, member-major so
/// that the members of one dispatch come back as a few contiguous ranges:
///
/// * residual region: per member slot `m`, at `m * residual_per_member()`, its node
///   residuals (`A_NODE` per node slot, node after node) then its three row-scale maxima
///   (u, θ, g);
/// * tangent region, from `tangent_start()`: per member slot, at
///   `tangent_start() + m * tangent_per_member()`, its node diagonal blocks (`A_BLOCK`
///   per node slot, row-major) then its element off-diagonal blocks ((0,1) then (1,0),
///   `A_BLOCK` each).
///
/// A residual-only iteration reads back the residual region of the waiting members only.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AsmLayout {
    /// Member slots.
    pub members: usize,
    /// Node slots per member.
    pub nodes_per_slot: usize,
    /// Element slots per member.
    pub per_slot: usize,
}

impl AsmLayout {
    /// Scalars of one member's residual region (node residuals and scales).
    pub fn residual_per_member(&self) -> usize {
        A_NODE * self.nodes_per_slot + 3
    }
    /// Scalars of one member's tangent region (node and off-diagonal blocks).
    pub fn tangent_per_member(&self) -> usize {
        A_BLOCK * (self.nodes_per_slot + 2 * self.per_slot)
    }
    /// Start of the tangent region.
    pub fn tangent_start(&self) -> usize {
        self.members * self.residual_per_member()
    }
    /// Scalars of the whole buffer.
    pub fn len(&self) -> usize {
        self.tangent_start() + self.members * self.tangent_per_member()
    }
    /// Always false (a layout has at least one slot of each kind); for clippy's `len`.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
    /// First of the `A_NODE` residual rows of node `j` of member `m`.
    pub fn node_residual(&self, m: usize, j: usize) -> usize {
        m * self.residual_per_member() + A_NODE * j
    }
    /// First of the three row-scale maxima of member `m`.
    pub fn scales(&self, m: usize) -> usize {
        m * self.residual_per_member() + A_NODE * self.nodes_per_slot
    }
    /// First entry of the diagonal block of node `j` of member `m`.
    pub fn node_block(&self, m: usize, j: usize) -> usize {
        self.tangent_start() + m * self.tangent_per_member() + A_BLOCK * j
    }
    /// First entry of off-diagonal block `h` (0: (0,1), 1: (1,0)) of element `e` of
    /// member `m`.
    pub fn off_block(&self, m: usize, e: usize, h: usize) -> usize {
        self.node_block(m, self.nodes_per_slot) + A_BLOCK * (2 * e + h)
    }
}
