//! Lanes: the scalar type the 3D element kernel is written over. The kernel exists once,
//! generic over [`Lane`]; it runs on `f64` (one element) and on [`F64x4`] (four elements
//! at once, one per lane: the CPU assembly's SIMD path).
//!
//! Every lane operation is the same IEEE operation as on `f64`, lane by lane (no fused
//! multiply-add, no reassociation), so the four lanes of an `F64x4` evaluation equal four
//! `f64` evaluations bit for bit for finite inputs (`tests/lanes.rs`). Branches on data
//! become lane selects; a branch that only skips work that would add an exact zero
//! (`dw ≠ 0`, β ≠ 0 under the mid-point rule) is taken when any lane needs it, and adds
//! that zero in the others (a NaN there instead of skipping it, were an input infinite).

use std::fmt::Debug;
use std::ops::{Add, AddAssign, Div, DivAssign, Mul, MulAssign, Neg, Sub, SubAssign};

use nalgebra::{Matrix3, Scalar};
use num_traits::{One, Zero};

/// Number of elements an [`F64x4`] evaluation carries.
pub const LANES: usize = 4;

/// A scalar of the element kernel: `f64`, or one `f64` per lane.
pub trait Lane:
    Scalar
    + Copy
    + Debug
    + Default
    + Zero
    + One
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
    + AddAssign
    + SubAssign
    + MulAssign
    + DivAssign
    + Send
    + Sync
{
    /// Per-element flag: `bool`, or one per lane.
    type Flag: Copy + Debug + PartialEq + Send + Sync;
    /// The same value in every lane.
    fn splat(x: f64) -> Self;
    /// `f64::max`, lane by lane. (For `F64x4`: the same where the operands are not NaN
    /// and not zeros of opposite signs; the kernel takes it of magnitudes only.)
    fn max(self, other: Self) -> Self;
    /// `if other > self { other } else { self }`, lane by lane (plain compares: see
    /// `element::amax3`).
    fn max_gt(self, other: Self) -> Self;
    /// `|x|`, lane by lane.
    fn abs(self) -> Self;
    /// `√x`, lane by lane.
    fn sqrt(self) -> Self;
    /// `value` where `flag`, else 0, lane by lane.
    fn select_or_zero(flag: Self::Flag, value: Self) -> Self;
    /// Whether any lane is nonzero.
    fn any_nonzero(self) -> bool;
    /// `a` where `flag`, else `b`, lane by lane.
    fn choose(flag: Self::Flag, a: Self, b: Self) -> Self;
    /// Lanes per value.
    const WIDTH: usize;
    /// The lanes of a slice of values as one `f64` slice: value `j`'s lane `i` at
    /// `j * WIDTH + i` (plain loads where the scatter reads one lane of each value).
    fn flat(s: &[Self]) -> &[f64];
}

impl Lane for f64 {
    type Flag = bool;
    const WIDTH: usize = 1;
    #[inline(always)]
    fn flat(s: &[Self]) -> &[f64] {
        s
    }
    #[inline(always)]
    fn splat(x: f64) -> Self {
        x
    }
    #[inline(always)]
    fn max(self, other: Self) -> Self {
        f64::max(self, other)
    }
    #[inline(always)]
    fn max_gt(self, other: Self) -> Self {
        if other > self {
            other
        } else {
            self
        }
    }
    #[inline(always)]
    fn abs(self) -> Self {
        f64::abs(self)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    #[inline(always)]
    fn select_or_zero(flag: bool, value: Self) -> Self {
        if flag {
            value
        } else {
            0.0
        }
    }
    #[inline(always)]
    fn any_nonzero(self) -> bool {
        self != 0.0
    }
    #[inline(always)]
    fn choose(flag: bool, a: Self, b: Self) -> Self {
        if flag {
            a
        } else {
            b
        }
    }
}

/// Four `f64` lanes, one element each: a `wide::f64x4` (one AVX register; two SSE2
/// registers where the build does not target AVX), whose arithmetic is the plain IEEE
/// operation lane by lane.
#[derive(Clone, Copy, Default, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(transparent)]
pub struct F64x4(pub wide::f64x4);

impl Debug for F64x4 {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.0.to_array().fmt(f)
    }
}

impl F64x4 {
    /// Lane `i`.
    #[inline(always)]
    pub fn lane(self, i: usize) -> f64 {
        self.0.as_array()[i]
    }
    /// The four lanes.
    #[inline(always)]
    pub fn new(x: [f64; LANES]) -> Self {
        F64x4(wide::f64x4::new(x))
    }
    /// All-ones bits where `flag`, zero elsewhere (a select mask).
    #[inline(always)]
    fn flags(flag: [bool; LANES]) -> wide::f64x4 {
        let m = |b: bool| if b { f64::from_bits(u64::MAX) } else { 0.0 };
        wide::f64x4::new([m(flag[0]), m(flag[1]), m(flag[2]), m(flag[3])])
    }
}

macro_rules! lane_op {
    ($tr:ident, $f:ident, $atr:ident, $af:ident, $op:tt) => {
        impl $tr for F64x4 {
            type Output = F64x4;
            #[inline(always)]
            fn $f(self, o: F64x4) -> F64x4 {
                F64x4(self.0 $op o.0)
            }
        }
        impl $atr for F64x4 {
            #[inline(always)]
            fn $af(&mut self, o: F64x4) {
                self.0 = self.0 $op o.0;
            }
        }
    };
}
lane_op!(Add, add, AddAssign, add_assign, +);
lane_op!(Sub, sub, SubAssign, sub_assign, -);
lane_op!(Mul, mul, MulAssign, mul_assign, *);

impl Div for F64x4 {
    type Output = F64x4;
    #[inline(always)]
    fn div(self, o: F64x4) -> F64x4 {
        F64x4(self.0 / o.0)
    }
}

impl DivAssign for F64x4 {
    #[inline(always)]
    fn div_assign(&mut self, o: F64x4) {
        self.0 = self.0 / o.0;
    }
}

impl Neg for F64x4 {
    type Output = F64x4;
    #[inline(always)]
    fn neg(self) -> F64x4 {
        F64x4(-self.0)
    }
}

impl Zero for F64x4 {
    #[inline(always)]
    fn zero() -> Self {
        F64x4(wide::f64x4::ZERO)
    }
    #[inline(always)]
    fn is_zero(&self) -> bool {
        !self.any_nonzero()
    }
}

impl One for F64x4 {
    #[inline(always)]
    fn one() -> Self {
        F64x4(wide::f64x4::ONE)
    }
}

impl Lane for F64x4 {
    type Flag = [bool; LANES];
    const WIDTH: usize = LANES;
    #[inline(always)]
    fn flat(s: &[Self]) -> &[f64] {
        bytemuck::cast_slice(s)
    }
    #[inline(always)]
    fn splat(x: f64) -> Self {
        F64x4(wide::f64x4::splat(x))
    }
    #[inline(always)]
    fn max(self, o: Self) -> Self {
        // wide's `max` takes the other lane where one is NaN, like `f64::max`.
        F64x4(self.0.max(o.0))
    }
    #[inline(always)]
    fn max_gt(self, o: Self) -> Self {
        F64x4(o.0.simd_gt(self.0).select(o.0, self.0))
    }
    #[inline(always)]
    fn abs(self) -> Self {
        F64x4(self.0.abs())
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        F64x4(self.0.sqrt())
    }
    #[inline(always)]
    fn select_or_zero(flag: [bool; LANES], value: Self) -> Self {
        F64x4(Self::flags(flag).select(value.0, wide::f64x4::ZERO))
    }
    #[inline(always)]
    fn any_nonzero(self) -> bool {
        self.0.simd_ne(wide::f64x4::ZERO).any()
    }
    #[inline(always)]
    fn choose(flag: [bool; LANES], a: Self, b: Self) -> Self {
        F64x4(Self::flags(flag).select(a.0, b.0))
    }
}

/// The zero matrix of any fixed size, built as an array of zeros: nalgebra's `zeros()` fills
/// a generic scalar through an iterator, which for [`F64x4`] compiles to a slow element
/// loop (for `f64` both are a plain fill).
#[inline(always)]
pub fn zeros<T: Lane, const R: usize, const C: usize>() -> nalgebra::SMatrix<T, R, C> {
    nalgebra::SMatrix::from_array_storage(nalgebra::ArrayStorage([[T::zero(); R]; C]))
}

/// The 3×3 identity, built like [`zeros`].
#[inline(always)]
pub fn identity3<T: Lane>() -> Matrix3<T> {
    let (z, o) = (T::zero(), T::one());
    Matrix3::new(o, z, z, z, o, z, z, z, o)
}
