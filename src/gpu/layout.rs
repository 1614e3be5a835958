//! Struct-of-arrays layout of the kernel buffers: field `f` of element `i` lives at
//! `f * capacity + i`. Twin of the `E_*`, `S_*`, `I_*`, `O_*` constants at the top of
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
/// Number of element-constant fields.
pub const NE: usize = 34;

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
/// Active flag (1 = evaluate).
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

/// Node-local unknowns (`u0..2 θ0..2 g0..2`) of the assembled system.
pub const A_NODE: usize = 9;
/// Entries of one 9×9 block (row-major).
pub const A_BLOCK: usize = A_NODE * A_NODE;

/// Layout of the assembled buffer written by `shaders/assemble.wgsl` (field-major, field
/// `f` of slot `j` at `offset + f * slots + j`). The node residuals and member scales lead
/// and are contiguous, so a residual-only iteration reads back one range.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct AsmLayout {
    /// Node slots.
    pub nodes: usize,
    /// Member slots.
    pub members: usize,
    /// Element slots.
    pub elements: usize,
}

impl AsmLayout {
    /// Node residuals (`A_NODE` fields per node slot) start at 0; the member scales (3
    /// fields per member slot: u, θ, g) start here.
    pub fn scales(&self) -> usize {
        A_NODE * self.nodes
    }
    /// Scalars of the residual-only readback (node residuals and member scales).
    pub fn residual_len(&self) -> usize {
        self.scales() + 3 * self.members
    }
    /// Node diagonal blocks (`A_BLOCK` fields per node slot).
    pub fn node_blocks(&self) -> usize {
        self.residual_len()
    }
    /// Element off-diagonal blocks (0,1) then (1,0) (`2 A_BLOCK` fields per element slot).
    pub fn off_blocks(&self) -> usize {
        self.node_blocks() + A_BLOCK * self.nodes
    }
    /// Scalars of the whole buffer.
    pub fn len(&self) -> usize {
        self.off_blocks() + 2 * A_BLOCK * self.elements
    }
    /// Always false (a layout has at least one slot of each kind); for clippy's `len`.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}
