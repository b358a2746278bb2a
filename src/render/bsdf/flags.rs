//! What a model is, as typed values: its lobes (Mitsuba 3's `BSDFFlags`, pbrt-v4's
//! `BxDFFlags`) and the properties that decide which machinery a scene needs
//! ([`crate::render::effects`]), and the lobe mask of sampling ([`Lobes`], pbrt-v4's
//! `BxDFReflTransFlags`).

use std::fmt;
use std::ops::{BitOr, BitOrAssign};

/// Lobes and properties of a BSDF.
#[derive(Clone, Copy, PartialEq, Eq, Default, Hash)]
pub struct BsdfFlags(u32);

impl BsdfFlags {
    pub const NONE: Self = Self(0);
    /// Lambertian-like reflection.
    pub const DIFFUSE_REFLECTION: Self = Self(1 << 0);
    pub const DIFFUSE_TRANSMISSION: Self = Self(1 << 1);
    /// Microfacet (rough) reflection.
    pub const GLOSSY_REFLECTION: Self = Self(1 << 2);
    pub const GLOSSY_TRANSMISSION: Self = Self(1 << 3);
    /// Mirror reflection (a Dirac delta).
    pub const DELTA_REFLECTION: Self = Self(1 << 4);
    /// Refraction or straight transmission (a Dirac delta).
    pub const DELTA_TRANSMISSION: Self = Self(1 << 5);
    /// Light passes straight through, direction unchanged (Mitsuba's `Null`): polarisers,
    /// opacity masks. A transmission lobe.
    pub const NULL: Self = Self(1 << 6);

    /// Scatters light arriving from either side of the surface (otherwise only from the side
    /// the shading normal points to).
    pub const TWO_SIDED: Self = Self(1 << 8);
    /// The refracted direction depends on wavelength: the path's secondary wavelengths are
    /// terminated there (hero-wavelength sampling).
    pub const DISPERSIVE: Self = Self(1 << 9);
    /// The model acts on polarisation itself (a polariser): the scene is rendered with
    /// Stokes vectors.
    pub const NEEDS_POLARIZATION: Self = Self(1 << 10);
    /// Thin-film interference of one film (the Airy sum).
    pub const INTERFERENCE: Self = Self(1 << 11);
    /// A multilayer coating (the transfer-matrix method).
    pub const MULTILAYER: Self = Self(1 << 12);
    /// A film thickness that varies over the surface (a texture).
    pub const THICKNESS_MAP: Self = Self(1 << 13);
    /// Reads the mesh's vertex colours (a shape without them is refused).
    pub const VERTEX_COLOR: Self = Self(1 << 14);

    pub const REFLECTION: Self =
        Self(Self::DIFFUSE_REFLECTION.0 | Self::GLOSSY_REFLECTION.0 | Self::DELTA_REFLECTION.0);
    pub const TRANSMISSION: Self = Self(
        Self::DIFFUSE_TRANSMISSION.0
            | Self::GLOSSY_TRANSMISSION.0
            | Self::DELTA_TRANSMISSION.0
            | Self::NULL.0,
    );
    /// Lobes with a density (light sampling applies): diffuse and glossy.
    pub const SMOOTH: Self = Self(
        Self::DIFFUSE_REFLECTION.0
            | Self::DIFFUSE_TRANSMISSION.0
            | Self::GLOSSY_REFLECTION.0
            | Self::GLOSSY_TRANSMISSION.0,
    );
    pub const GLOSSY: Self = Self(Self::GLOSSY_REFLECTION.0 | Self::GLOSSY_TRANSMISSION.0);
    /// Dirac lobes (no light sampling, no MIS).
    pub const DELTA: Self =
        Self(Self::DELTA_REFLECTION.0 | Self::DELTA_TRANSMISSION.0 | Self::NULL.0);
    pub const LOBES: Self = Self(Self::REFLECTION.0 | Self::TRANSMISSION.0);

    /// Every flag of `other` is set.
    #[inline]
    pub const fn contains(self, other: Self) -> bool {
        self.0 & other.0 == other.0
    }

    /// Some flag of `other` is set.
    #[inline]
    pub const fn intersects(self, other: Self) -> bool {
        self.0 & other.0 != 0
    }

    /// Only the lobe flags.
    #[inline]
    pub const fn lobes(self) -> Self {
        Self(self.0 & Self::LOBES.0)
    }

    /// `self` with `flag` set when `on`.
    #[inline]
    pub const fn with(self, flag: Self, on: bool) -> Self {
        if on {
            Self(self.0 | flag.0)
        } else {
            self
        }
    }

    /// `self` without the flags of `other`.
    #[inline]
    pub const fn without(self, other: Self) -> Self {
        Self(self.0 & !other.0)
    }
}

impl BitOr for BsdfFlags {
    type Output = Self;
    #[inline]
    fn bitor(self, rhs: Self) -> Self {
        Self(self.0 | rhs.0)
    }
}

impl BitOrAssign for BsdfFlags {
    #[inline]
    fn bitor_assign(&mut self, rhs: Self) {
        self.0 |= rhs.0;
    }
}

impl fmt::Debug for BsdfFlags {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        const NAMES: [&str; 15] = [
            "diffuse reflection",
            "diffuse transmission",
            "glossy reflection",
            "glossy transmission",
            "delta reflection",
            "delta transmission",
            "null",
            "",
            "two-sided",
            "dispersive",
            "needs polarisation",
            "interference",
            "multilayer",
            "thickness map",
            "vertex colour",
        ];
        let set: Vec<&str> = (0..NAMES.len())
            .filter(|&i| self.0 & (1 << i) != 0)
            .map(|i| NAMES[i])
            .collect();
        write!(f, "BsdfFlags({})", set.join(" | "))
    }
}

/// Which lobes [`super::BsdfModel::sample`] may choose from.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Lobes(u8);

impl Lobes {
    pub const REFLECTION: Self = Self(1);
    pub const TRANSMISSION: Self = Self(2);
    pub const ALL: Self = Self(3);

    /// Reflection lobes may be sampled.
    #[inline]
    pub const fn reflection(self) -> bool {
        self.0 & 1 != 0
    }

    /// Transmission lobes may be sampled.
    #[inline]
    pub const fn transmission(self) -> bool {
        self.0 & 2 != 0
    }

    /// Whether a sample of `lobe` (a lobe flag) is allowed.
    #[inline]
    pub const fn allows(self, lobe: BsdfFlags) -> bool {
        (self.reflection() && lobe.intersects(BsdfFlags::REFLECTION))
            || (self.transmission() && lobe.intersects(BsdfFlags::TRANSMISSION))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn composites_and_masks() {
        let glass = BsdfFlags::DELTA_REFLECTION | BsdfFlags::DELTA_TRANSMISSION;
        assert!(glass.contains(BsdfFlags::DELTA_REFLECTION));
        assert!(!glass.intersects(BsdfFlags::SMOOTH));
        assert_eq!((glass | BsdfFlags::TWO_SIDED).lobes(), glass);
        assert!(Lobes::REFLECTION.allows(BsdfFlags::GLOSSY_REFLECTION));
        assert!(!Lobes::REFLECTION.allows(BsdfFlags::NULL));
        assert!(Lobes::TRANSMISSION.allows(BsdfFlags::NULL));
        assert!(Lobes::ALL.allows(BsdfFlags::DIFFUSE_TRANSMISSION));
        assert_eq!(
            format!(
                "{:?}",
                BsdfFlags::INTERFERENCE.with(BsdfFlags::TWO_SIDED, true)
            ),
            "BsdfFlags(two-sided | interference)"
        );
    }
}
