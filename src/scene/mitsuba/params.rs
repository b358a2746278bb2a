//! Typed parameter access for the plugin builders next to their models
//! ([`crate::render::bsdf::BsdfPlugin::build`]): each getter takes a parameter off the
//! element (what is left over is an error naming it), checks its type and value, and reports
//! problems with the file, line and element.

// `!(x >= 0.0)` is deliberate throughout: it also rejects NaN.
#![allow(clippy::neg_cmp_op_on_partial_ord)]

use super::{mitsuba_ior, Ctx, Prop, Props, Val, MITSUBA_IOR_TABLE};
use crate::optics::{dispersion, Complex64, Ior};
use crate::render::bsdf::microfacet::Distribution;
use crate::render::bsdf::Bsdf;
use crate::scene::{BitmapTexture, SpectrumDesc, TextureDesc};
use anyhow::Result;
use roxmltree::Node;
use std::sync::Arc;

/// The parameters of one plugin element, for its builder.
pub struct PluginParams<'p, 'a, 'i> {
    props: &'p mut Props<'a, 'i>,
    ctx: &'p Ctx<'a, 'i>,
    /// Elements of the parameters taken so far, for [`PluginParams::error_at`].
    taken: Vec<(String, Node<'a, 'i>)>,
}

impl<'p, 'a, 'i> PluginParams<'p, 'a, 'i> {
    pub(super) fn new(props: &'p mut Props<'a, 'i>, ctx: &'p Ctx<'a, 'i>) -> Self {
        PluginParams {
            props,
            ctx,
            taken: Vec::new(),
        }
    }

    /// The plugin type (`type="…"`).
    pub fn plugin(&self) -> &str {
        &self.props.plugin
    }

    /// Whether parameter `name` is given (and not taken yet).
    pub fn has(&self, name: &str) -> bool {
        self.props.list.iter().any(|q| q.name == name)
    }

    /// Whether parameter `name` is given as a `<string>`.
    pub fn is_string(&self, name: &str) -> bool {
        self.props
            .list
            .iter()
            .any(|q| q.name == name && matches!(q.val, Val::Str(_)))
    }

    /// `file:line:col` of the plugin element, for notes and warnings.
    pub fn location(&self) -> String {
        self.ctx.loc(self.props.node)
    }

    /// An error at the plugin element.
    pub fn error(&self, msg: impl std::fmt::Display) -> anyhow::Error {
        self.ctx.err(self.props.node, msg)
    }

    /// An error at parameter `name`'s element (taken or not), else at the plugin element.
    pub fn error_at(&self, name: &str, msg: impl std::fmt::Display) -> anyhow::Error {
        let node = self
            .taken
            .iter()
            .rev()
            .find(|(n, _)| n == name)
            .map(|(_, node)| *node)
            .or_else(|| {
                self.props
                    .list
                    .iter()
                    .find(|q| q.name == name)
                    .map(|q| q.node)
            });
        self.ctx.err(node.unwrap_or(self.props.node), msg)
    }

    fn take(&mut self, name: &str) -> Option<Prop<'a, 'i>> {
        let q = self.props.take(name)?;
        self.taken.push((name.to_string(), q.node));
        Some(q)
    }

    pub fn float_opt(&mut self, name: &str) -> Result<Option<f64>> {
        match self.take(name) {
            None => Ok(None),
            Some(q) => match q.val {
                Val::Float(v) if v.is_finite() => Ok(Some(v)),
                Val::Int(v) => Ok(Some(v as f64)),
                _ => Err(Props::type_err(self.ctx, &q, "a finite <float>")),
            },
        }
    }

    pub fn float(&mut self, name: &str, default: f64) -> Result<f64> {
        Ok(self.float_opt(name)?.unwrap_or(default))
    }

    /// A number given as a `<float>` or a constant `<spectrum>` (e.g. an angle).
    pub fn constant(&mut self, name: &str, default: f64) -> Result<f64> {
        match self.take(name) {
            None => Ok(default),
            Some(q) => match q.val {
                Val::Float(v) => Ok(v),
                Val::Int(v) => Ok(v as f64),
                Val::Spectrum(SpectrumDesc::Constant(v)) => Ok(v as f64),
                _ => Err(Props::type_err(self.ctx, &q, "a constant <float>")),
            },
        }
    }

    pub fn bool(&mut self, name: &str, default: bool) -> Result<bool> {
        self.props.bool(self.ctx, name, default)
    }

    pub fn string(&mut self, name: &str) -> Result<Option<String>> {
        match self.take(name) {
            None => Ok(None),
            Some(q) => match q.val {
                Val::Str(v) => Ok(Some(v)),
                _ => Err(Props::type_err(self.ctx, &q, "a <string>")),
            },
        }
    }

    /// A value or a `<texture>` (reflectances, weights; a `mesh_attribute` too: BSDFs
    /// evaluate textures through [`crate::render::texture::Texture::eval_at`] and say in
    /// their flags that they read one, `BsdfFlags::VERTEX_COLOR`).
    pub fn texture(&mut self, name: &str, default: f32) -> Result<TextureDesc> {
        self.props.texture(self.ctx, name, default)
    }

    /// Accepts a `<boolean>` parameter Mitsuba has and this renderer ignores, if `ok(value)`.
    pub fn accept_bool(&mut self, name: &str, ok: impl Fn(bool) -> bool) -> Result<()> {
        self.props
            .accept(&[name], self.ctx, |v| matches!(v, Val::Bool(x) if ok(*x)))
    }

    /// A dielectric index as a number: a float or a Mitsuba IOR name.
    pub fn ior_number(&mut self, name: &str, default: f64) -> Result<f64> {
        self.props.ior_number(self.ctx, name, default)
    }

    /// The nested and referenced BSDFs, in document order (taken off the element).
    pub fn bsdfs(&mut self) -> Result<Vec<Bsdf>> {
        let mut out = Vec::new();
        let mut rest = Vec::new();
        for q in std::mem::take(&mut self.props.list) {
            match q.val {
                Val::Bsdf(b) => out.push(b),
                Val::BsdfRef(i) => out.push(self.ctx.bsdfs[i].clone()),
                _ => rest.push(q),
            }
        }
        self.props.list = rest;
        Ok(out)
    }

    /// The nested `<texture>` children whatever their names (Mitsuba's `bumpmap` takes its
    /// height from any one), in document order (taken off the element).
    pub fn nested_textures(&mut self) -> Vec<TextureDesc> {
        let (textures, rest): (Vec<_>, Vec<_>) = std::mem::take(&mut self.props.list)
            .into_iter()
            .partition(|q| matches!(q.val, Val::Texture(_)));
        self.props.list = rest;
        (textures.into_iter())
            .filter_map(|q| match q.val {
                Val::Texture(t) => Some(t),
                _ => None,
            })
            .collect()
    }

    /// A real value that may depend on wavelength: a number or a tabulated `<spectrum>`.
    pub fn real_spectrum(&mut self, name: &str) -> Result<Option<RealSpectrum>> {
        self.real_spectrum_as(name, name)
    }

    /// [`Self::real_spectrum`], naming the parameter `what` in errors.
    pub fn real_spectrum_as(&mut self, name: &str, what: &str) -> Result<Option<RealSpectrum>> {
        match self.take(name) {
            None => Ok(None),
            Some(q) => self.spectral_of(&q, what).map(Some),
        }
    }

    /// n + ik from two real spectra (a constant, or a tabulated material named after the
    /// element and `what`).
    pub fn complex_index(&self, n: &RealSpectrum, k: &RealSpectrum, what: &str) -> Ior {
        combine_ior(&format!("{} {what}", self.ctx.loc(self.props.node)), n, k)
    }

    /// A film or substrate index: a number or spectrum, `n+ki`, a material of the dispersion
    /// library, a Mitsuba IOR name, or a formula (`cauchy:…`, `sellmeier:…`).
    pub fn index(&mut self, name: &str, default: Ior) -> Result<Ior> {
        match self.take(name) {
            None => Ok(default),
            Some(q) => self.index_of(&q, name),
        }
    }

    /// A multilayer string parameter ("MgF2:100, TiO2:50"; [`parse_layers`]).
    pub fn layers(&mut self, name: &str) -> Result<Option<Vec<(Ior, f64)>>> {
        let Some(q) = self.take(name) else {
            return Ok(None);
        };
        let Val::Str(text) = &q.val else {
            return Err(self.ctx.err(
                q.node,
                format!("{name} must be a <string> of layers, e.g. \"MgF2:100, TiO2:50\""),
            ));
        };
        parse_layers(text)
            .map(Some)
            .map_err(|e| self.ctx.err(q.node, format!("{name}: {e}")))
    }

    /// Film thickness in nm (`thickness`): a float ≥ 0 or a (single-channel) bitmap or
    /// checkerboard texture.
    pub fn film_thickness(&mut self, default: f32) -> Result<TextureDesc> {
        let Some(q) = self.take("thickness") else {
            return Ok(TextureDesc::Value(SpectrumDesc::Constant(default)));
        };
        Ok(match q.val {
            Val::Float(v) if v.is_finite() && v >= 0.0 => {
                TextureDesc::Value(SpectrumDesc::Constant(v as f32))
            }
            Val::Float(v) => {
                return Err(self
                    .ctx
                    .err(q.node, format!("thickness {v} nm must be ≥ 0")))
            }
            Val::Texture(TextureDesc::Bitmap(b)) => {
                TextureDesc::Bitmap(Arc::new(single_channel(&b)))
            }
            Val::Texture(t @ TextureDesc::Checkerboard { .. }) => t,
            ref v => {
                return Err(self.ctx.err(
                    q.node,
                    format!(
                        "thickness must be a float or a bitmap texture, not {}",
                        v.kind()
                    ),
                ))
            }
        })
    }

    /// A dielectric's `int_ior`/`ext_ior`: a float or a Mitsuba IOR name (constant, as in
    /// Mitsuba — so `bk7` is 1.5046 everywhere Mitsuba renders the scene too); a dispersive
    /// index from `material:NAME`, `cauchy:…`, `sellmeier:…` (see [`Ior`]'s parser), a name of
    /// the dispersion library that is not in Mitsuba's table (e.g. `SiO2`), or a tabulated
    /// `<spectrum>` of λ:n pairs.
    pub fn dielectric_ior(&mut self, name: &str, default: f64) -> Result<Ior> {
        let Some(q) = self.take(name) else {
            return Ok(Ior::real(default));
        };
        let ior = match &q.val {
            Val::Str(s) => {
                if let Some(v) = mitsuba_ior(s) {
                    Ior::real(v)
                } else {
                    s.parse::<Ior>().map_err(|e| {
                        let names: Vec<_> = MITSUBA_IOR_TABLE.iter().map(|(n, _)| *n).collect();
                        self.ctx.err(
                            q.node,
                            format!(
                                "{name}: unknown IOR name \"{s}\" ({e}); Mitsuba IOR names: {}; dispersive: material:NAME, cauchy:A,B[,C], sellmeier:B1,C1,…",
                                names.join(", ")
                            ),
                        )
                    })?
                }
            }
            _ => {
                let n = self.spectral_of(&q, name)?;
                if !(n.min() > 0.0) {
                    return Err(self.ctx.err(q.node, format!("{name} must be > 0")));
                }
                combine_ior(
                    &format!("{} {name}", self.ctx.loc(q.node)),
                    &n,
                    &RealSpectrum::Const(0.0),
                )
            }
        };
        let c = ior.at(550.0);
        if !(c.re > 0.0 && c.re.is_finite()) {
            return Err(self.ctx.err(q.node, format!("{name} must be > 0")));
        }
        if c.im != 0.0 {
            return Err(self.ctx.err(
                q.node,
                format!("{name} = {ior} absorbs (k > 0): a dielectric needs a real index (use conductor)"),
            ));
        }
        Ok(ior)
    }

    /// `distribution` (Mitsuba's default `beckmann`, or `ggx`) and `alpha` or
    /// `alpha_u`/`alpha_v` (default 0.1) of a rough plugin. α_u applies along the shading
    /// tangent dp/du, as in Mitsuba ([`crate::render::bsdf::normal_map::dpdu_frame`]).
    /// `sample_visible` changes only the noise (the renderer always samples visible normals).
    pub fn microfacet(&mut self) -> Result<(Distribution, f32, f32)> {
        let kind = self.distribution()?;
        let alpha = self.float_opt("alpha")?;
        let au = self.float_opt("alpha_u")?;
        let av = self.float_opt("alpha_v")?;
        let (u, v) = match (alpha, au, av) {
            (Some(a), None, None) => (a, a),
            (None, Some(u), Some(v)) => (u, v),
            (None, None, None) => (0.1, 0.1),
            _ => {
                return Err(self.ctx.err(
                    self.props.node,
                    "give either 'alpha' or both 'alpha_u' and 'alpha_v'",
                ))
            }
        };
        if !(u >= 0.0 && v >= 0.0) {
            return Err(self.ctx.err(self.props.node, "roughness must be ≥ 0"));
        }
        Ok((kind, u as f32, v as f32))
    }

    /// `distribution` (Mitsuba's default `beckmann`, or `ggx`); takes `sample_visible` too
    /// (it changes only the noise: visible normals are always sampled).
    pub fn distribution(&mut self) -> Result<Distribution> {
        let dist = self.string("distribution")?;
        let kind = match dist.as_deref() {
            Some("ggx") => Distribution::Ggx,
            Some("beckmann") | None => Distribution::Beckmann,
            Some(other) => {
                return Err(self.ctx.err(
                    self.props.node,
                    format!("unknown distribution \"{other}\" (ggx, beckmann)"),
                ))
            }
        };
        self.accept_bool("sample_visible", |_| true)?;
        Ok(kind)
    }

    /// Whether parameter `name` is given as a plain number (not a texture, RGB or spectrum).
    pub fn is_number(&self, name: &str) -> bool {
        self.props.list.iter().any(|q| {
            q.name == name
                && matches!(
                    q.val,
                    Val::Float(_) | Val::Int(_) | Val::Spectrum(SpectrumDesc::Constant(_))
                )
        })
    }

    /// A conductor's `eta` or `k`: a number, a tabulated `<spectrum>`, or an `<rgb>` —
    /// upsampled as Mitsuba 3's spectral variants do (`get_unbounded_texture` → its `srgb`
    /// plugin: each component clamped to [0, 1] by `rgb2spec_fetch`, then the Jakob–Hanika
    /// sigmoid polynomial), tabulated here at 1 nm over the visible range.
    pub fn conductor_spectrum(&mut self, name: &str, what: &str) -> Result<Option<RealSpectrum>> {
        match self.take(name) {
            Some(q) => match q.val {
                Val::Rgb(c) => {
                    let poly = crate::spectrum::srgb_reflectance(c);
                    let table = (360..=830)
                        .map(|l| (l as f32, poly.eval(l as f32)))
                        .collect();
                    Ok(Some(RealSpectrum::Table(table)))
                }
                _ => self.spectral_of(&q, what).map(Some),
            },
            None => Ok(None),
        }
    }

    /// A conductor `material`: Mitsuba's `none`, a metal of the dispersion library, or one
    /// of Mitsuba's own conductor tables ([`mitsuba_conductor`]) — used for the names the
    /// library lacks (`a-C`, `Cr`, …) and for those it has only as a transparent dielectric
    /// (`TiO2`), where Mitsuba's `conductor` means its absorbing table.
    pub fn conductor_material(&self, name: &str) -> Result<Ior> {
        if name == "none" {
            // Mitsuba's "none": a perfect mirror, eta = 0, k = 1 (|r| = 1 at every angle).
            return Ok(Ior::Constant(Complex64::new(0.0, 1.0)));
        }
        let own = dispersion::lookup(name).map(Ior::Material);
        if let Some(ior) = own.as_ref().filter(|m| m.at(550.0).im > 0.0) {
            return Ok(ior.clone());
        }
        let label = format!(
            "{} Mitsuba conductor \"{name}\"",
            self.ctx.loc(self.props.node)
        );
        mitsuba_conductor(name, &label).or(own).ok_or_else(|| {
            let names = dispersion::names();
            self.ctx.err(
                self.props.node,
                format!(
                    "unknown conductor material \"{name}\" (available: none, {}, and Mitsuba's {})",
                    names.join(", "),
                    mitsuba_conductor_names().join(", ")
                ),
            )
        })
    }

    /// A real value that may depend on wavelength: a number or a tabulated `<spectrum>`.
    fn spectral_of(&self, q: &Prop, what: &str) -> Result<RealSpectrum> {
        match &q.val {
            Val::Float(v) if v.is_finite() => Ok(RealSpectrum::Const(*v)),
            Val::Int(v) => Ok(RealSpectrum::Const(*v as f64)),
            Val::Spectrum(SpectrumDesc::Constant(v)) => Ok(RealSpectrum::Const(*v as f64)),
            Val::Spectrum(SpectrumDesc::Tabulated(t)) => Ok(RealSpectrum::Table(t.clone())),
            v => Err(self.ctx.err(
                q.node,
                format!(
                    "{what} must be a number or a <spectrum> of λ:value pairs, not {}: RGB-valued indices are not supported (Mitsuba upsamples them like colours; a measured index is a spectrum)",
                    v.kind()
                ),
            )),
        }
    }

    /// A film/substrate index: a number, or a name from the dispersion library or
    /// Mitsuba's IOR table.
    fn index_of(&self, q: &Prop, what: &str) -> Result<Ior> {
        let ior = match &q.val {
            Val::Str(s) => {
                if let Some(m) = dispersion::lookup(s) {
                    Ior::Material(m)
                } else if let Some(v) = mitsuba_ior(s) {
                    Ior::real(v)
                } else {
                    s.parse::<Ior>()
                        .map_err(|e| self.ctx.err(q.node, format!("{what}: {e}")))?
                }
            }
            _ => {
                let n = self.spectral_of(q, what)?;
                if !(n.min() > 0.0) {
                    return Err(self.ctx.err(q.node, format!("{what} must be > 0")));
                }
                combine_ior(
                    &format!("{} {what}", self.ctx.loc(q.node)),
                    &n,
                    &RealSpectrum::Const(0.0),
                )
            }
        };
        if let Ior::Constant(c) = ior {
            if !(c.re > 0.0 && c.re.is_finite()) {
                return Err(self.ctx.err(q.node, format!("{what} must be > 0")));
            }
        }
        Ok(ior)
    }
}

/// Mitsuba 3's conductor tables (`data/ior/NAME.{eta,k}.spd`, 300–900 nm), one line per name
/// and quantity: `NAME eta λ:v λ:v …` / `NAME k …`.
const MITSUBA_CONDUCTORS: &str = include_str!("conductors.txt");

/// The names of [`MITSUBA_CONDUCTORS`].
fn mitsuba_conductor_names() -> Vec<&'static str> {
    MITSUBA_CONDUCTORS
        .lines()
        .filter(|l| !l.starts_with('#'))
        .filter_map(|l| l.split_whitespace().next())
        .fold(Vec::new(), |mut v, n| {
            if v.last() != Some(&n) {
                v.push(n);
            }
            v
        })
}

/// Mitsuba's conductor `name` as n + ik (linear interpolation between its samples, as its
/// `irregular` spectrum), or None if Mitsuba has no such table.
fn mitsuba_conductor(name: &str, label: &str) -> Option<Ior> {
    let table = |quantity: &str| -> Option<RealSpectrum> {
        let line = MITSUBA_CONDUCTORS.lines().find(|l| {
            let mut w = l.split_whitespace();
            w.next() == Some(name) && w.next() == Some(quantity)
        })?;
        let rows: Option<Vec<(f32, f32)>> = line
            .split_whitespace()
            .skip(2)
            .map(|pair| {
                let (l, v) = pair.split_once(':')?;
                Some((l.parse().ok()?, v.parse().ok()?))
            })
            .collect();
        Some(RealSpectrum::Table(rows?))
    };
    Some(combine_ior(label, &table("eta")?, &table("k")?))
}

/// A thickness texture must be scalar: RGB images are reduced to their mean.
fn single_channel(b: &BitmapTexture) -> BitmapTexture {
    if b.channels == 1 {
        return b.clone();
    }
    let data = b
        .data
        .chunks_exact(b.channels)
        .map(|c| c.iter().sum::<f32>() / c.len() as f32)
        .collect();
    BitmapTexture {
        channels: 1,
        data,
        ..b.clone()
    }
}

/// A real quantity that may depend on wavelength: a number or a tabulated `<spectrum>`.
#[derive(Debug, Clone)]
pub enum RealSpectrum {
    Const(f64),
    /// (λ nm, value), strictly increasing λ.
    Table(Vec<(f32, f32)>),
}

impl RealSpectrum {
    /// Linear interpolation, constant beyond the ends (Mitsuba's `regular`/`irregular`
    /// spectra clamp the same way for conductor data).
    fn at(&self, lambda_nm: f64) -> f64 {
        match self {
            RealSpectrum::Const(v) => *v,
            RealSpectrum::Table(t) => {
                let l = lambda_nm as f32;
                let i = t.partition_point(|p| p.0 < l);
                let v = if i == 0 {
                    t[0].1
                } else if i == t.len() {
                    t[t.len() - 1].1
                } else {
                    let (a, b) = (t[i - 1], t[i]);
                    a.1 + (b.1 - a.1) * (l - a.0) / (b.0 - a.0)
                };
                v as f64
            }
        }
    }

    /// The smallest value.
    pub fn min(&self) -> f64 {
        match self {
            RealSpectrum::Const(v) => *v,
            RealSpectrum::Table(t) => t.iter().map(|p| p.1 as f64).fold(f64::INFINITY, f64::min),
        }
    }
}

/// n + ik from two real spectra: a constant if both are constant, otherwise a tabulated
/// material on the union of their wavelength grids. The material is leaked to obtain the
/// `&'static` that [`Ior::Material`] holds: a few hundred bytes per spectral index per loaded
/// scene.
pub(super) fn combine_ior(label: &str, n: &RealSpectrum, k: &RealSpectrum) -> Ior {
    if let (RealSpectrum::Const(n), RealSpectrum::Const(k)) = (n, k) {
        return Ior::Constant(Complex64::new(*n, *k));
    }
    let mut grid: Vec<f32> = [n, k]
        .iter()
        .flat_map(|s| match s {
            RealSpectrum::Table(t) => t.iter().map(|p| p.0).collect(),
            RealSpectrum::Const(_) => Vec::new(),
        })
        .collect();
    grid.sort_by(f32::total_cmp);
    grid.dedup();
    let rows: Vec<(f64, f64, f64)> = grid
        .iter()
        .map(|&l| (l as f64, n.at(l as f64), k.at(l as f64)))
        .collect();
    let range = (rows[0].0, rows[rows.len() - 1].0);
    let material = dispersion::Material {
        name: Box::leak(label.to_string().into_boxed_str()),
        aliases: Vec::new(),
        source: "tabulated in the scene file",
        valid_range_nm: range,
        model: dispersion::Model::Table(rows),
    };
    Ior::Material(Box::leak(Box::new(material)))
}

/// Parses a `layers` string: comma- or semicolon-separated `index:thickness_nm` items, top
/// (ambient side) first. The index is a number (`1.38`), `n+ki` (`2.0+0.1i`) or a material
/// of the dispersion library (`MgF2`, `TiO2`, `SiO2`, …). A group in parentheses followed by
/// `xN` repeats N times: `(TiO2:52, SiO2:94)x6, TiO2:52` is a 13-layer quarter-wave mirror.
pub fn parse_layers(text: &str) -> std::result::Result<Vec<(Ior, f64)>, String> {
    const MAX_LAYERS: usize = 10_000;
    fn items(text: &str) -> std::result::Result<Vec<&str>, String> {
        let mut out = Vec::new();
        let (mut depth, mut start) = (0i32, 0);
        for (i, ch) in text.char_indices() {
            match ch {
                '(' => depth += 1,
                ')' => {
                    depth -= 1;
                    if depth < 0 {
                        return Err(format!("unbalanced ')' in \"{text}\""));
                    }
                }
                ',' | ';' if depth == 0 => {
                    out.push(text[start..i].trim());
                    start = i + 1;
                }
                _ => {}
            }
        }
        if depth != 0 {
            return Err(format!("unbalanced '(' in \"{text}\""));
        }
        out.push(text[start..].trim());
        Ok(out)
    }
    fn parse(
        text: &str,
        out: &mut Vec<(Ior, f64)>,
        level: usize,
    ) -> std::result::Result<(), String> {
        for item in items(text)? {
            if item.is_empty() {
                return Err(format!("empty layer in \"{text}\""));
            }
            if let Some(body) = item.strip_prefix('(') {
                let close = body
                    .rfind(')')
                    .ok_or_else(|| format!("'{item}': missing ')'"))?;
                let count = body[close + 1..].trim();
                let count = count
                    .strip_prefix(['x', 'X', '*'])
                    .and_then(|c| c.trim().parse::<usize>().ok())
                    .filter(|&n| (1..=1000).contains(&n))
                    .ok_or_else(|| {
                        format!("'{item}': a group must end in xN with 1 ≤ N ≤ 1000, e.g. (TiO2:52, SiO2:94)x6")
                    })?;
                if level > 4 {
                    return Err("groups nested too deeply".into());
                }
                let mut group = Vec::new();
                parse(&body[..close], &mut group, level + 1)?;
                if out.len() + group.len().saturating_mul(count) > MAX_LAYERS {
                    return Err(format!("'{item}' makes more than {MAX_LAYERS} layers"));
                }
                for _ in 0..count {
                    out.extend(group.iter().cloned());
                }
                continue;
            }
            let (material, thickness) = item.rsplit_once(':').ok_or_else(|| {
                format!("layer '{item}' must be index:thickness_nm, e.g. MgF2:100")
            })?;
            let d: f64 = thickness.trim().parse().map_err(|_| {
                format!(
                    "layer '{item}': thickness '{}' is not a number (nm)",
                    thickness.trim()
                )
            })?;
            if !(d.is_finite() && d >= 0.0) {
                return Err(format!(
                    "layer '{item}': thickness must be finite and ≥ 0 nm"
                ));
            }
            let ior: Ior = material
                .trim()
                .parse()
                .map_err(|e| format!("layer '{item}': {e}"))?;
            crate::limits::check_index(format!("layer '{item}'"), &ior)
                .map_err(|e| e.to_string())?;
            out.push((ior, d));
            if out.len() > MAX_LAYERS {
                return Err(format!("more than {MAX_LAYERS} layers"));
            }
        }
        Ok(())
    }
    let mut out = Vec::new();
    parse(text, &mut out, 0)?;
    Ok(out)
}
