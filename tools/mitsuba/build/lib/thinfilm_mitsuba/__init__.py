"""thinfilm's BSDFs for Mitsuba 3, written in Python, with the parameters of thinfilm's own
thin-film BSDF (scenes/README.md lists them):

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

Multilayer coatings (thinfilm's `thinfilm` with a `layers` string):

    <bsdf type="thinfilm">
      <string name="layers" value="MgF2:99.6"/>     index:thickness_nm, top first; (A:1, B:2)xN repeats
      <string name="substrate_ior" value="BK7"/>    number or a material of src/optics/data/dielectrics.txt
      <float name="alpha" value="0.1"/>             optional GGX roughness
    </bsdf>

R is the unpolarised transfer-matrix reflectance (Rouard recursion, float64) with each
layer's dispersive index at each of the path's wavelengths, read from the same data file as
the Rust optics library (Sellmeier / pole / Cauchy formulas).

Free-standing films (`thinfilm_bubble`, a soap bubble): a film of float `film_ior` and
`thickness` (float or bitmap texture, nm) with the same ambient `ext_ior` (float, default 1)
on both sides; coherent Airy R and T (s and p averaged), two-sided; reflection is the mirror
direction, transmission goes straight through (weight T, eta 1); the lobe is chosen with
probability mean(R) / (mean(R) + mean(T)) over the four wavelengths.

Coated glass (`coateddielectric`: float `int_ior`, `ext_ior` (default 1.000277), string
`coating` of lossless layers on the outside): R from the stack seen from the side the light
arrives on, T = 1 - R, Snell refraction between the bulk media, Mitsuba dielectric weights.

Install (from the repository root; Mitsuba 3 itself comes from `pip install mitsuba`):

    pip install ./tools/mitsuba

Use: `import thinfilm_mitsuba; thinfilm_mitsuba.setup(variant)` after which scene files with
`<bsdf type="thinfilm">`, `"thinfilm_bubble"` and `"coateddielectric"` load, including the
`material.xml` that `thinfilm estimate` writes (its thickness.exr has one channel `Y`, which
Mitsuba's `bitmap` texture reads as-is with `raw="true"`).
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


# --- dispersive materials (the Rust library's data file) and transfer-matrix stacks ---

# The Rust library's src/optics/data/dielectrics.txt, shipped inside the package (a symbolic
# link in the repository, copied when the package is installed).
DIELECTRICS = os.path.join(os.path.dirname(os.path.abspath(__file__)), "dielectrics.txt")


def _load_dielectrics():
    """name (lower case, and aliases) -> (model, coefficients) from dielectrics.txt."""
    out = {}
    with open(DIELECTRICS) as f:
        for line in f:
            line = line.strip()
            if not line or line.startswith("#"):
                continue
            name, aliases, model, _range, coeffs, _source = [x.strip() for x in line.split("|")]
            c = []
            for tok in coeffs.split(","):
                tok = tok.strip()
                c.append(float(tok[:-2]) ** 2 if tok.endswith("^2") else float(tok))
            for n in [name] + [a for a in aliases.split(",") if a.strip()]:
                out[n.strip().lower()] = (model, c)
    return out


def material_index(name_or_value, lambda_nm, dr=None):
    """Real refractive index of a number or a named dielectric at lambda_nm (float or drjit
    Float64), with the same formulas as src/optics/dispersion.rs."""
    try:
        return float(name_or_value) + 0.0 * lambda_nm
    except ValueError:
        pass
    table = _load_dielectrics()
    key = str(name_or_value).strip().lower()
    if key not in table:
        raise ValueError(f"unknown material '{name_or_value}' (known: {sorted(table)})")
    model, c = table[key]
    l2 = (lambda_nm * 1e-3) * (lambda_nm * 1e-3)
    sqrt = dr.sqrt if dr is not None else math.sqrt
    if model == "sellmeier":
        n2 = c[0]
        for b, cc in zip(c[1::2], c[2::2]):
            n2 = n2 + b * l2 / (l2 - cc)
        return sqrt(n2)
    if model == "poles":
        n2 = c[0]
        for b, cc in zip(c[1::2], c[2::2]):
            n2 = n2 + b / (l2 - cc)
        return sqrt(n2)
    if model == "cauchy":
        return c[0] + c[1] / l2 + c[2] / (l2 * l2)
    raise ValueError(f"model {model}")


def parse_layers(text):
    """`MgF2:100, TiO2:50`, `(TiO2:51.9, SiO2:94.2)x6, TiO2:51.9` -> [(index spec, nm), ...]
    (the syntax of thinfilm's scene parser, src/scene/mitsuba.rs parse_layers)."""
    items, depth, start = [], 0, 0
    for i, ch in enumerate(text):
        if ch == "(":
            depth += 1
        elif ch == ")":
            depth -= 1
        elif ch in ",;" and depth == 0:
            items.append(text[start:i].strip())
            start = i + 1
    items.append(text[start:].strip())
    out = []
    for item in items:
        if item.startswith("("):
            close = item.rindex(")")
            count = int(item[close + 1 :].strip().lstrip("xX*"))
            out.extend(parse_layers(item[1:close]) * count)
        else:
            name, d = item.rsplit(":", 1)
            out.append((name.strip(), float(d)))
    return out


def stack_reflectance(dr, lambda_nm, cos_i, layers, substrate, ambient=1.0):
    """Unpolarised reflectance of air | layers (real indices: names or numbers) | substrate
    by the Rouard recursion r_j = (r_{j-1,j} + r_{j+1} e^{2i beta_j}) / (1 + r_{j-1,j} r_{j+1} e^{2i beta_j}),
    float64. Works on drjit Float64 arrays or Python floats (then dr may be the math-like shim)."""
    cos_i = dr.clip(cos_i, 0.0, 1.0)
    kx2 = ambient * ambient * (1.0 - cos_i * cos_i)
    zero = 0.0 * cos_i
    media = [(ambient + zero, zero)]
    for name, _d in layers:
        media.append((material_index(name, lambda_nm, dr) + zero, zero))
    media.append((material_index(substrate, lambda_nm, dr) + zero, zero))
    nsq = [_cmul(n, n) for n in media]
    nc = [(ambient * cos_i, zero)] + [_csqrt_upper((q[0] - kx2, q[1]), dr) for q in nsq[1:]]

    def r_if(i, f, pol):
        if pol == "s":
            return _cdiv(_csub(nc[i], nc[f]), _cadd(nc[i], nc[f]))
        x = _cmul(nsq[f], nc[i])
        y = _cmul(nsq[i], nc[f])
        return _cdiv(_csub(x, y), _cadd(x, y))

    total = 0.0
    last = len(media) - 1
    for pol in ("s", "p"):
        r = r_if(last - 1, last, pol)
        for j in range(last - 1, 0, -1):
            k = 4.0 * math.pi * layers[j - 1][1] / lambda_nm
            ph = (nc[j][0] * k, nc[j][1] * k)
            decay = dr.exp(-ph[1])
            sn, cs = dr.sincos(ph[0])
            e = (decay * cs, decay * sn)
            rij = r_if(j - 1, j, pol)
            re = _cmul(r, e)
            r = _cdiv(_cadd(rij, re), _cadd((1.0, 0.0), _cmul(rij, re)))
        total = total + 0.5 * (r[0] * r[0] + r[1] * r[1])
    return total


def bubble_rt(dr, lambda_nm, cos_i, film_ior, thickness_nm, ext_ior=1.0):
    """Unpolarised (R, T) of a free-standing lossless film n_f between two media n_a, float64:
    r = (r12 + r23 E)/(1 + r12 r23 E), t = t12 t23 e^{i beta}/(1 + r12 r23 E), E = e^{2i beta};
    T = |t|^2 (the same medium on both sides)."""
    cos_i = dr.clip(dr.abs(cos_i), 0.0, 1.0)
    zero = 0.0 * cos_i
    na = ext_ior
    kx2 = na * na * (1.0 - cos_i * cos_i)
    a = (na * cos_i, zero)
    b = _csqrt_upper((film_ior * film_ior - kx2 + zero, zero), dr)
    k = 2.0 * math.pi * thickness_nm / lambda_nm
    ph = (b[0] * k, b[1] * k)  # beta
    decay = dr.exp(-ph[1])
    sn, cs = dr.sincos(ph[0])
    e1 = (decay * cs, decay * sn)  # e^{i beta}
    e2 = _cmul(e1, e1)
    rsum, tsum = 0.0, 0.0
    # Admittances y: s uses n cos, p uses n cos / n^2. For p the field amplitudes t carry
    # extra n_i/n_f factors that cancel over the two interfaces (n_a -> n_f -> n_a), so
    # t = t12 t23 e^{i beta} / den holds in admittance form for both polarisations.
    for ya, yb in (
        (a, b),
        (_cdiv(a, (na * na, 0.0)), _cdiv(b, (film_ior * film_ior, 0.0))),
    ):
        r12 = _cdiv(_csub(ya, yb), _cadd(ya, yb))
        r23 = _cdiv(_csub(yb, ya), _cadd(yb, ya))
        t12 = _cdiv((2.0 * ya[0], 2.0 * ya[1]), _cadd(ya, yb))
        t23 = _cdiv((2.0 * yb[0], 2.0 * yb[1]), _cadd(yb, ya))
        den = _cadd((1.0, 0.0), _cmul(_cmul(r12, r23), e2))
        r = _cdiv(_cadd(r12, _cmul(r23, e2)), den)
        t = _cdiv(_cmul(_cmul(t12, t23), e1), den)
        rsum = rsum + 0.5 * (r[0] * r[0] + r[1] * r[1])
        tsum = tsum + 0.5 * (t[0] * t[0] + t[1] * t[1])
    return rsum, tsum


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
            self.layers = None
            if props.has_property("layers"):
                self.layers = parse_layers(props.get("layers"))
                self.substrate_name = str(props.get("substrate_ior", "1.64"))
                for name, _d in self.layers + [(self.substrate_name, 0.0)]:
                    material_index(name, 550.0)  # unknown names fail at load time
            self.film_ior = float(props.get("film_ior", 1.37))
            self.substrate_ior = (
                1.64 if self.layers is not None else float(props.get("substrate_ior", 1.64))
            )
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
                if self.layers is not None:
                    r = stack_reflectance(dr, lam, c, self.layers, self.substrate_name)
                else:
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

    class BubbleBSDF(mi.BSDF):
        """Free-standing film (see the module docstring): two delta lobes, two-sided."""

        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            self.film_ior = float(props.get("film_ior", 1.33))
            self.ext_ior = float(props.get("ext_ior", 1.0))
            t = props.get("thickness", 400.0)
            if isinstance(t, mi.Texture):
                self.thickness_tex, self.thickness_const = t, None
            else:
                self.thickness_tex, self.thickness_const = None, float(t)
            if not (self.film_ior > 0 and self.ext_ior > 0):
                raise ValueError("thinfilm_bubble: indices must be > 0")
            sides = mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide
            extra = mi.BSDFFlags.SpatiallyVarying if self.thickness_tex is not None else mi.BSDFFlags(0)
            refl = mi.BSDFFlags.DeltaReflection | sides | extra
            trans = mi.BSDFFlags.DeltaTransmission | sides | extra
            self.m_components = [refl, trans]
            self.m_flags = refl | trans

        def _rt(self, si, cos_i, active):
            if self.thickness_tex is None:
                d = mi.Float64(self.thickness_const)
            else:
                d = mi.Float64(self.thickness_tex.eval_1(si, active))
            d = dr.maximum(d, 0.0)
            c = mi.Float64(cos_i)
            rs, ts = [], []
            for i in range(4):
                r, t = bubble_rt(dr, mi.Float64(si.wavelengths[i]), c, self.film_ior, d, self.ext_ior)
                rs.append(mi.Float(r))
                ts.append(mi.Float(t))
            return mi.Spectrum(*rs), mi.Spectrum(*ts)

        def sample(self, ctx, si, sample1, sample2, active=True):
            cos_i = mi.Frame3f.cos_theta(si.wi)
            active = mi.Bool(active) & (cos_i != 0)
            r, t = self._rt(si, cos_i, active)
            r_sum = r[0] + r[1] + r[2] + r[3]
            t_sum = t[0] + t[1] + t[2] + t[3]
            p_r = dr.select(r_sum + t_sum > 0, r_sum / (r_sum + t_sum), 0.5)
            has_r = ctx.is_enabled(mi.BSDFFlags.DeltaReflection, 0)
            has_t = ctx.is_enabled(mi.BSDFFlags.DeltaTransmission, 1)
            if not has_r:
                p_r = mi.Float(0.0)
            if not has_t:
                p_r = mi.Float(1.0)
            reflect = sample1 < p_r
            bs = mi.BSDFSample3f()
            bs.wo = dr.select(reflect, mi.reflect(si.wi), -si.wi)
            bs.pdf = dr.select(reflect, p_r, 1.0 - p_r)
            bs.eta = mi.Float(1.0)
            bs.sampled_type = dr.select(
                reflect, mi.UInt32(+mi.BSDFFlags.DeltaReflection), mi.UInt32(+mi.BSDFFlags.DeltaTransmission)
            )
            bs.sampled_component = dr.select(reflect, mi.UInt32(0), mi.UInt32(1))
            weight = dr.select(reflect, r / p_r, t / (1.0 - p_r))
            active &= bs.pdf > 0
            return (bs, dr.select(active, weight, 0.0))

        def eval(self, ctx, si, wo, active=True):
            return mi.Spectrum(0.0)

        def pdf(self, ctx, si, wo, active=True):
            return mi.Float(0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            return (mi.Spectrum(0.0), mi.Float(0.0))

        def to_string(self):
            t = "texture" if self.thickness_tex is not None else f"{self.thickness_const} nm"
            return f"BubbleBSDF[film_ior={self.film_ior}, thickness={t}, ext_ior={self.ext_ior}]"

    mi.register_bsdf("thinfilm_bubble", lambda props: BubbleBSDF(props))

    class CoatedDielectricBSDF(mi.BSDF):
        """Smooth dielectric under a lossless multilayer coating on its outside
        (`coateddielectric`): R from the stack seen from the arriving side, T = 1 - R,
        refraction by Snell between ext_ior and int_ior, weights as Mitsuba's dielectric."""

        def __init__(self, props):
            mi.BSDF.__init__(self, props)
            self.int_ior = float(props.get("int_ior", 1.5046))
            self.ext_ior = float(props.get("ext_ior", 1.000277))
            self.layers = parse_layers(props.get("coating"))
            for name, _d in self.layers:
                material_index(name, 550.0)
            self.eta = self.int_ior / self.ext_ior
            sides = mi.BSDFFlags.FrontSide | mi.BSDFFlags.BackSide
            self.m_components = [
                mi.BSDFFlags.DeltaReflection | sides,
                mi.BSDFFlags.DeltaTransmission | sides | mi.BSDFFlags.NonSymmetric,
            ]
            self.m_flags = self.m_components[0] | self.m_components[1]

        def sample(self, ctx, si, sample1, sample2, active=True):
            cos_i = mi.Frame3f.cos_theta(si.wi)
            inside = cos_i < 0
            c = mi.Float64(dr.abs(cos_i))
            rs = []
            for i in range(4):
                lam = mi.Float64(si.wavelengths[i])
                r_out = stack_reflectance(dr, lam, c, self.layers, self.int_ior, self.ext_ior)
                r_in = stack_reflectance(dr, lam, c, self.layers[::-1], self.ext_ior, self.int_ior)
                rs.append(mi.Float(dr.select(mi.Bool(inside), r_in, r_out)))
            r = mi.Spectrum(*rs)
            t = 1.0 - r
            p_r = dr.clip((rs[0] + rs[1] + rs[2] + rs[3]) * 0.25, 0.0, 1.0)
            if not ctx.is_enabled(mi.BSDFFlags.DeltaTransmission, 1):
                p_r = mi.Float(1.0)
            if not ctx.is_enabled(mi.BSDFFlags.DeltaReflection, 0):
                p_r = mi.Float(0.0)
            _f, cos_t, eta_it, eta_ti = mi.fresnel(cos_i, mi.Float(self.eta))
            reflect = sample1 < p_r
            bs = mi.BSDFSample3f()
            bs.wo = dr.select(reflect, mi.reflect(si.wi), mi.refract(si.wi, cos_t, eta_ti))
            bs.pdf = dr.select(reflect, p_r, 1.0 - p_r)
            bs.eta = dr.select(reflect, mi.Float(1.0), eta_it)
            bs.sampled_type = dr.select(
                reflect, mi.UInt32(+mi.BSDFFlags.DeltaReflection), mi.UInt32(+mi.BSDFFlags.DeltaTransmission)
            )
            bs.sampled_component = dr.select(reflect, mi.UInt32(0), mi.UInt32(1))
            # Radiance is compressed by eta^2 entering the denser medium (Mitsuba dielectric).
            weight = dr.select(reflect, r / p_r, t / (1.0 - p_r) * dr.square(eta_ti))
            active = mi.Bool(active) & (bs.pdf > 0) & (cos_i != 0)
            return (bs, dr.select(active, weight, 0.0))

        def eval(self, ctx, si, wo, active=True):
            return mi.Spectrum(0.0)

        def pdf(self, ctx, si, wo, active=True):
            return mi.Float(0.0)

        def eval_pdf(self, ctx, si, wo, active=True):
            return (mi.Spectrum(0.0), mi.Float(0.0))

        def to_string(self):
            return f"CoatedDielectricBSDF[int_ior={self.int_ior}, ext_ior={self.ext_ior}, coating={self.layers}]"

    mi.register_bsdf("coateddielectric", lambda props: CoatedDielectricBSDF(props))


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
    # Free-standing film (bubble) R and T, and multilayer stacks with dispersive materials.
    for n2, d in ((1.33, 0.0), (1.33, 350.0), (1.45, 1200.0)):
        for t in angles:
            for l in lams:
                ref = [tmm.coh_tmm(pol, [1.0, n2, 1.0], [np.inf, d, np.inf], t, l) for pol in "sp"]
                r_ref = 0.5 * (ref[0]["R"] + ref[1]["R"])
                t_ref = 0.5 * (ref[0]["T"] + ref[1]["T"])
                r, tt = bubble_rt(dr, mi.Float64(l), mi.Float64(math.cos(t)), n2, mi.Float64(d))
                err = max(abs(_scalar(r) - r_ref), abs(_scalar(tt) - t_ref))
                worst = max(worst, err)
        log(f"  tmm check bubble n={n2} d={d}: R and T within {worst:.2e}")
    for layers, sub in (
        ("MgF2:99.6", "BK7"),
        ("MgF2:100, TiO2:50", "PET"),
        ("(TiO2:51.9, SiO2:94.2)x6, TiO2:51.9", "BK7"),
    ):
        ls = parse_layers(layers)
        err_stack = 0.0
        for t in angles:
            for l in lams:
                ns = [1.0] + [material_index(n, l) for n, _ in ls] + [material_index(sub, l)]
                ds = [np.inf] + [d for _, d in ls] + [np.inf]
                r_ref = 0.5 * sum(tmm.coh_tmm(pol, ns, ds, t, l)["R"] for pol in "sp")
                r = stack_reflectance(dr, mi.Float64(l), mi.Float64(math.cos(t)), ls, sub)
                err_stack = max(err_stack, abs(_scalar(r) - r_ref))
        worst = max(worst, err_stack)
        log(f"  tmm check stack [{layers}] on {sub}: max |R - R_tmm| = {err_stack:.2e}")
    # Seen from inside the glass (coated dielectric), including total internal reflection.
    ls = parse_layers("MgF2:99.6")
    err_in = 0.0
    for t in np.radians([0.0, 20.0, 40.0, 41.0, 60.0]):
        for l in lams:
            n_glass = 1.5168
            ns = [n_glass, material_index("MgF2", l), 1.000277]
            r_ref = 0.5 * sum(tmm.coh_tmm(pol, ns, [np.inf, 99.6, np.inf], t, l)["R"] for pol in "sp")
            r = stack_reflectance(dr, mi.Float64(l), mi.Float64(math.cos(t)), ls[::-1], 1.000277, n_glass)
            err_in = max(err_in, abs(_scalar(r) - r_ref))
    worst = max(worst, err_in)
    log(f"  tmm check coating seen from inside BK7-like glass (incl. TIR): max |R - R_tmm| = {err_in:.2e}")
    if worst > tolerance:
        raise AssertionError(f"Airy reflectance differs from tmm by {worst} > {tolerance}")
    return worst


def _scalar(v):
    import numpy as np

    return float(np.array(v, dtype=np.float64).ravel()[0])
