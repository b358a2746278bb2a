"""A `thinfilm` BSDF for Mitsuba 3, written in Python, with the parameters of thinfilm's own
thin-film BSDF (see shared docs design.md, "The thin-film BSDF in scene files"):

    <bsdf type="thinfilm">
      <float name="film_ior" value="1.37"/>         film index n2 (real)
      <float name="thickness" value="400"/>         nm; or <texture type="bitmap" name="thickness">
      <float name="substrate_ior" value="1.64"/>    substrate n3
      <float name="substrate_k" value="0"/>         substrate extinction k3 (> 0 for metals)
      <float name="alpha" value="0.1"/>             optional: rough GGX (alpha = 0 -> smooth)
    </bsdf>

The film is opaque: what is transmitted into the substrate is absorbed. Reflectance is the
unpolarised Airy sum (seed eq. 4): r = (r12 + r23 e^{i2beta}) / (1 + r12 r23 e^{i2beta}),
beta = 2 pi d n2 cos(theta2) / lambda, R = (|r_s|^2 + |r_p|^2) / 2, ambient n1 = 1.
It is evaluated in float64 (in float32 the error reaches ~2e-5 at grazing angles).

Smooth: a delta reflection with weight R(theta_i). Rough: a GGX microfacet BRDF
f = R(wi.h) D(h) G(wi, wo) / (4 cos_i cos_o), sampled from GGX visible normals, with
Mitsuba's separable Smith G (as in its roughconductor).

Use: `import thinfilm_mitsuba; thinfilm_mitsuba.setup(variant)` after which scene files with
`<bsdf type="thinfilm">` load.
"""

import math
import os

DEFAULT_LLVM = "/usr/lib/x86_64-linux-gnu/libLLVM.so.19.1"


def setup(variant=None):
    """Selects a spectral variant (llvm_ad_spectral, falling back to scalar_spectral) and
    registers the plugin. Returns the variant name in use."""
    if "DRJIT_LIBLLVM_PATH" not in os.environ and os.path.exists(DEFAULT_LLVM):
        os.environ["DRJIT_LIBLLVM_PATH"] = DEFAULT_LLVM
    import mitsuba as mi

    tried = [variant] if variant else ["llvm_ad_spectral", "scalar_spectral"]
    last = None
    for v in tried:
        try:
            mi.set_variant(v)
            if v.startswith("llvm"):
                # Force JIT initialisation now so a missing LLVM falls back here.
                import drjit as dr

                dr.eval(mi.Float(1.0) + 1.0)
            break
        except Exception as e:  # noqa: BLE001 - report and fall back
            last = e
    else:
        raise RuntimeError(f"no usable Mitsuba variant among {tried}: {last}")
    _register(mi)
    return mi.variant()


# --- complex float64 arithmetic on (re, im) pairs; works on drjit arrays and Python floats ---


def _cmul(a, b):
    return (a[0] * b[0] - a[1] * b[1], a[0] * b[1] + a[1] * b[0])


def _cadd(a, b):
    return (a[0] + b[0], a[1] + b[1])


def _csub(a, b):
    return (a[0] - b[0], a[1] - b[1])


def _cdiv(a, b):
    den = b[0] * b[0] + b[1] * b[1]
    return ((a[0] * b[0] + a[1] * b[1]) / den, (a[1] * b[0] - a[0] * b[1]) / den)


def _csqrt_upper(z, dr):
    """Square root with Im >= 0 for Im z >= 0 (the forward-wave branch of n cos(theta) for
    n = n + ik with k >= 0, the branch tmm chooses)."""
    mag = dr.sqrt(z[0] * z[0] + z[1] * z[1])
    re = dr.sqrt(dr.maximum((mag + z[0]) * 0.5, 0.0))
    im = dr.sqrt(dr.maximum((mag - z[0]) * 0.5, 0.0))
    return (re, im)


def airy_reflectance(dr, lambda_nm, cos_i, film_ior, thickness_nm, substrate_ior, substrate_k):
    """Unpolarised reflectance of air | film (n2 real) | substrate (n3 + i k3), float64.
    Arguments may be Python floats or drjit Float64 arrays."""
    cos_i = dr.clip(cos_i, 0.0, 1.0)
    kx2 = 1.0 - cos_i * cos_i  # (n1 sin theta1)^2 with n1 = 1
    n1c = (cos_i, 0.0 * cos_i)
    n2sq = (film_ior * film_ior, 0.0 * cos_i)
    n3 = (substrate_ior + 0.0 * cos_i, substrate_k + 0.0 * cos_i)
    n3sq = _cmul(n3, n3)
    n2c = _csqrt_upper((n2sq[0] - kx2, n2sq[1]), dr)
    n3c = _csqrt_upper((n3sq[0] - kx2, n3sq[1]), dr)
    n1sq = (1.0 + 0.0 * cos_i, 0.0 * cos_i)

    def rs(ai, af):
        return _cdiv(_csub(ai, af), _cadd(ai, af))

    def rp(ni_sq, ai, nf_sq, af):
        # (nf cos_i - ni cos_f)/(nf cos_i + ni cos_f) = (nf^2 ai - ni^2 af)/(nf^2 ai + ni^2 af)
        x = _cmul(nf_sq, ai)
        y = _cmul(ni_sq, af)
        return _cdiv(_csub(x, y), _cadd(x, y))

    # 2 beta = 4 pi d n2 cos(theta2) / lambda (complex in general; real here for real n2
    # above the critical angle, which n2 >= 1 guarantees).
    k = 4.0 * math.pi * thickness_nm / lambda_nm
    ph = (n2c[0] * k, n2c[1] * k)
    decay = dr.exp(-ph[1])
    s, c = dr.sincos(ph[0])
    e = (decay * c, decay * s)
    total = 0.0
    for r12, r23 in (
        (rs(n1c, n2c), rs(n2c, n3c)),
        (rp(n1sq, n1c, n2sq, n2c), rp(n2sq, n2c, n3sq, n3c)),
    ):
        num = _cadd(r12, _cmul(r23, e))
        den = _cadd((1.0, 0.0), _cmul(_cmul(r12, r23), e))
        r = _cdiv(num, den)
        total = total + 0.5 * (r[0] * r[0] + r[1] * r[1])
    return total


def _register(mi):
    import drjit as dr

    class ThinFilmBSDF(mi.BSDF):
        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            for bad in ("material", "film_material"):
                if props.has_property(bad):
                    raise ValueError(
                        f"thinfilm (Python plugin): '{bad}' (named dispersion) is not supported; "
                        "give film_ior as a float"
                    )
            self.film_ior = float(props.get("film_ior", 1.37))
            self.substrate_ior = float(props.get("substrate_ior", 1.64))
            self.substrate_k = float(props.get("substrate_k", 0.0))
            self.alpha = float(props.get("alpha", 0.0))
            t = props.get("thickness", 400.0)
            if isinstance(t, mi.Texture):
                self.thickness_tex = t
                self.thickness_const = None
            else:
                self.thickness_tex = None
                self.thickness_const = float(t)
            if not (self.film_ior > 0 and self.substrate_ior > 0 and self.substrate_k >= 0):
                raise ValueError(
                    f"thinfilm: bad indices film_ior={self.film_ior} "
                    f"substrate_ior={self.substrate_ior} substrate_k={self.substrate_k}"
                )
            if self.alpha < 0:
                raise ValueError(f"thinfilm: alpha must be >= 0, got {self.alpha}")
            self.smooth = self.alpha == 0.0
            lobe = (
                mi.BSDFFlags.DeltaReflection if self.smooth else mi.BSDFFlags.GlossyReflection
            )
            flags = lobe | mi.BSDFFlags.FrontSide
            if self.thickness_tex is not None:
                flags = flags | mi.BSDFFlags.SpatiallyVarying
            self.m_components = [flags]
            self.m_flags = flags

        def _thickness(self, si, active):
            if self.thickness_tex is None:
                return mi.Float64(self.thickness_const)
            return mi.Float64(self.thickness_tex.eval_1(si, active))

        def _fresnel(self, si, cos_i, active):
            d = self._thickness(si, active)
            c = mi.Float64(cos_i)
            vals = []
            for i in range(4):
                lam = mi.Float64(si.wavelengths[i])
                r = airy_reflectance(
                    dr, lam, c, self.film_ior, d, self.substrate_ior, self.substrate_k
                )
                vals.append(mi.Float(r))
            return mi.Spectrum(vals[0], vals[1], vals[2], vals[3])

        def _distr(self):
            return mi.MicrofacetDistribution(mi.MicrofacetType.GGX, self.alpha, True)

        def sample(self, ctx, si, sample1, sample2, active=True):
            cos_i = mi.Frame3f.cos_theta(si.wi)
            bs = mi.BSDFSample3f()
            active = mi.Bool(active) & (cos_i > 0)
            if self.smooth:
                active &= ctx.is_enabled(mi.BSDFFlags.DeltaReflection, 0)
                bs.wo = mi.reflect(si.wi)
                bs.pdf = mi.Float(1.0)
                bs.eta = mi.Float(1.0)
                bs.sampled_type = mi.UInt32(+mi.BSDFFlags.DeltaReflection)
                bs.sampled_component = mi.UInt32(0)
                value = self._fresnel(si, cos_i, active)
                return (bs, dr.select(active, value, 0.0))
            active &= ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 0)
            distr = self._distr()
            m, pdf_m = distr.sample(si.wi, sample2)
            bs.wo = mi.reflect(si.wi, m)
            bs.eta = mi.Float(1.0)
            bs.sampled_type = mi.UInt32(+mi.BSDFFlags.GlossyReflection)
            bs.sampled_component = mi.UInt32(0)
            wo_dot_m = dr.dot(bs.wo, m)
            bs.pdf = pdf_m / (4.0 * wo_dot_m)
            active &= (pdf_m > 0) & (mi.Frame3f.cos_theta(bs.wo) > 0) & (wo_dot_m > 0)
            # Visible-normal sampling: weight = F(wi.m) G1(wo, m).
            weight = self._fresnel(si, dr.dot(si.wi, m), active) * distr.smith_g1(bs.wo, m)
            return (bs, dr.select(active, weight, 0.0))

        def eval(self, ctx, si, wo, active=True):
            if self.smooth:
                return mi.Spectrum(0.0)
            cos_i = mi.Frame3f.cos_theta(si.wi)
            cos_o = mi.Frame3f.cos_theta(wo)
            active = (
                mi.Bool(active)
                & (cos_i > 0)
                & (cos_o > 0)
                & ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 0)
            )
            h = dr.normalize(si.wi + wo)
            distr = self._distr()
            d = distr.eval(h)
            g = distr.G(si.wi, wo, h)
            f = self._fresnel(si, dr.dot(si.wi, h), active)
            # f * cos_o: the cos_o of the BRDF denominator cancels.
            value = f * (d * g / (4.0 * cos_i))
            return dr.select(active & (d > 0), value, 0.0)

        def pdf(self, ctx, si, wo, active=True):
            if self.smooth:
                return mi.Float(0.0)
            cos_i = mi.Frame3f.cos_theta(si.wi)
            cos_o = mi.Frame3f.cos_theta(wo)
            active = (
                mi.Bool(active)
                & (cos_i > 0)
                & (cos_o > 0)
                & ctx.is_enabled(mi.BSDFFlags.GlossyReflection, 0)
            )
            h = dr.normalize(si.wi + wo)
            distr = self._distr()
            p = distr.pdf(si.wi, h) / (4.0 * dr.dot(wo, h))
            return dr.select(active & (dr.dot(wo, h) > 0), p, 0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            return (self.eval(ctx, si, wo, active), self.pdf(ctx, si, wo, active))

        def to_string(self):
            t = "texture" if self.thickness_tex is not None else f"{self.thickness_const} nm"
            return (
                f"ThinFilmBSDF[film_ior={self.film_ior}, thickness={t}, "
                f"substrate_ior={self.substrate_ior}, substrate_k={self.substrate_k}, "
                f"alpha={self.alpha}]"
            )

    mi.register_bsdf("thinfilm", lambda props: ThinFilmBSDF(props))


def check_against_tmm(mi, tolerance=1e-9, log=print):
    """Checks airy_reflectance (as used by the plugin, on drjit Float64 arrays of the active
    variant) and the plugin's BSDF.sample weight against tmm.coh_tmm. Returns the max error."""
    import drjit as dr
    import numpy as np
    import tmm

    cases = [
        # film_ior, thickness_nm, substrate_ior, substrate_k
        (1.37, 400.0, 1.64, 0.0),
        (1.38, 120.0, 1.52, 0.0),
        (2.3, 250.0, 1.0, 0.0),
        (1.45, 900.0, 0.2, 3.0),  # silver-like substrate
        (1.6, 0.0, 1.5, 0.0),  # zero thickness -> bare substrate
    ]
    angles = np.radians([0.0, 20.0, 45.0, 70.0, 85.0, 89.0])
    lams = np.array([380.0, 450.0, 532.0, 600.0, 700.0, 780.0])
    worst = 0.0
    for n2, d, n3, k3 in cases:
        th, lam = np.meshgrid(angles, lams, indexing="ij")
        th, lam = th.ravel(), lam.ravel()
        ref = np.array(
            [
                0.5
                * sum(
                    tmm.coh_tmm(pol, [1.0, n2, n3 + 1j * k3], [np.inf, d, np.inf], t, l)["R"]
                    for pol in ("s", "p")
                )
                for t, l in zip(th, lam)
            ]
        )
        if mi.variant().startswith("scalar"):
            ours = np.array(
                [
                    airy_reflectance(dr, float(l), math.cos(t), n2, d, n3, k3)
                    for t, l in zip(th, lam)
                ]
            )
        else:
            ours = np.array(
                airy_reflectance(
                    dr, mi.Float64(lam), mi.Float64(np.cos(th)), n2, d, n3, k3
                )
            )
        err = float(np.max(np.abs(ours - ref)))
        worst = max(worst, err)
        log(f"  tmm check n2={n2} d={d} n3={n3}+{k3}i: max |R - R_tmm| = {err:.2e}")
    # The BSDF itself (smooth): sample weight must equal R at the incident angle.
    bsdf = mi.load_dict(
        {"type": "thinfilm", "film_ior": 1.37, "thickness": 400.0, "substrate_ior": 1.64}
    )
    for deg in (0.0, 30.0, 60.0, 80.0):
        si = dr.zeros(mi.SurfaceInteraction3f)
        t = math.radians(deg)
        si.wi = mi.Vector3f(math.sin(t), 0.0, math.cos(t))
        si.wavelengths = mi.Spectrum(450.0, 520.0, 600.0, 690.0)
        ctx = mi.BSDFContext()
        _, w = bsdf.sample(ctx, si, 0.5, mi.Point2f(0.5, 0.5), True)
        w = np.array(w).ravel()
        ref = np.array(
            [
                0.5
                * sum(
                    tmm.coh_tmm(pol, [1.0, 1.37, 1.64], [np.inf, 400.0, np.inf], t, l)["R"]
                    for pol in ("s", "p")
                )
                for l in (450.0, 520.0, 600.0, 690.0)
            ]
        )
        err = float(np.max(np.abs(w - ref)))
        # The weight is returned as float32 Spectrum.
        worst = max(worst, err - 1e-7)
        log(f"  BSDF.sample weight at {deg:4.1f} deg vs tmm: max error {err:.2e}")
        if err > 1e-6:
            raise AssertionError(f"plugin sample weight differs from tmm by {err} at {deg} deg")
    if worst > tolerance:
        raise AssertionError(f"Airy reflectance differs from tmm by {worst} > {tolerance}")
    return worst
