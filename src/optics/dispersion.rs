//! Dispersion library: `n(λ) + i k(λ)` of named materials.
//!
//! Dielectrics (MgF2, ZnS, SiO2, TiO2, water, PET, BK7) come from Sellmeier / pole /
//! Cauchy formulas in `data/dielectrics.txt`; metals (Al, Ag, Au, Cu) from tabulated n, k in
//! `data/<name>.csv`, interpolated linearly in wavelength exactly as Mitsuba 3's `conductor`
//! does with the same tables. Every data file cites its source in its header. The files
//! are compiled in (`include_str!`) and parsed once on first use; a malformed built-in
//! file is a programming error caught by the tests below.

use num_complex::Complex64;
use std::sync::OnceLock;

/// How a material's index is computed.
#[derive(Debug, Clone, PartialEq)]
pub enum Model {
    /// `n² = A + Σ B_i λ² / (λ² − C_i)`, λ in µm, `C_i` in µm².
    Sellmeier { a: f64, terms: Vec<(f64, f64)> },
    /// `n² = A + Σ B_i / (λ² − C_i)`, λ in µm, `C_i` in µm².
    Poles { a: f64, terms: Vec<(f64, f64)> },
    /// `n = A + B/λ² + C/λ⁴`, λ in µm.
    Cauchy { a: f64, b: f64, c: f64 },
    /// Tabulated `(λ nm, n, k)`, ascending λ; linear interpolation, constant beyond the ends.
    Table(Vec<(f64, f64, f64)>),
}

/// A named optical material.
#[derive(Debug, PartialEq)]
pub struct Material {
    /// Canonical name (`MgF2`, `Au`, …).
    pub name: &'static str,
    /// Other accepted names (case-insensitive).
    pub aliases: Vec<&'static str>,
    /// Where the numbers come from.
    pub source: &'static str,
    /// Wavelength range (nm) over which the source is valid; outside it we extrapolate
    /// (formulas) or hold the end values (tables).
    pub valid_range_nm: (f64, f64),
    pub model: Model,
}

impl Material {
    /// `n + ik` at `lambda_nm`.
    pub fn nk(&self, lambda_nm: f64) -> Complex64 {
        let l_um = lambda_nm * 1e-3;
        let l2 = l_um * l_um;
        match &self.model {
            Model::Sellmeier { a, terms } => {
                let n2 = terms.iter().fold(*a, |s, &(b, c)| s + b * l2 / (l2 - c));
                Complex64::new(n2.max(0.0).sqrt(), 0.0)
            }
            Model::Poles { a, terms } => {
                let n2 = terms.iter().fold(*a, |s, &(b, c)| s + b / (l2 - c));
                Complex64::new(n2.max(0.0).sqrt(), 0.0)
            }
            Model::Cauchy { a, b, c } => Complex64::new(a + b / l2 + c / (l2 * l2), 0.0),
            Model::Table(rows) => interpolate(rows, lambda_nm),
        }
    }

    /// [`Material::nk`] at `N` wavelengths: the formulas' terms added lane by lane in the
    /// same order (the same values bit for bit), so the divisions of the wavelengths run
    /// side by side in SIMD lanes.
    pub fn nk_lanes<const N: usize>(&self, lambda_nm: [f64; N]) -> [Complex64; N] {
        let l2: [f64; N] = super::lanes::lanes(|k| {
            let l_um = lambda_nm[k] * 1e-3;
            l_um * l_um
        });
        let real = |n: [f64; N]| n.map(|n| Complex64::new(n, 0.0));
        match &self.model {
            Model::Sellmeier { a, terms } => {
                let mut n2 = [*a; N];
                for &(b, c) in terms {
                    for k in 0..N {
                        n2[k] += b * l2[k] / (l2[k] - c);
                    }
                }
                real(n2.map(|n2| n2.max(0.0).sqrt()))
            }
            Model::Poles { a, terms } => {
                let mut n2 = [*a; N];
                for &(b, c) in terms {
                    for k in 0..N {
                        n2[k] += b / (l2[k] - c);
                    }
                }
                real(n2.map(|n2| n2.max(0.0).sqrt()))
            }
            Model::Cauchy { .. } | Model::Table(_) => lambda_nm.map(|l| self.nk(l)),
        }
    }

    /// Does `name` (case-insensitive) refer to this material?
    pub fn is_called(&self, name: &str) -> bool {
        self.name.eq_ignore_ascii_case(name)
            || self.aliases.iter().any(|a| a.eq_ignore_ascii_case(name))
    }
}

fn interpolate(rows: &[(f64, f64, f64)], lambda_nm: f64) -> Complex64 {
    let first = rows[0];
    let last = rows[rows.len() - 1];
    if lambda_nm.is_nan() {
        return Complex64::new(f64::NAN, f64::NAN);
    }
    if lambda_nm <= first.0 {
        return Complex64::new(first.1, first.2);
    }
    if lambda_nm >= last.0 {
        return Complex64::new(last.1, last.2);
    }
    let hi = walk_to_row_above(rows, lambda_nm, guess_row_above(rows, lambda_nm));
    let (l0, n0, k0) = rows[hi - 1];
    let (l1, n1, k1) = rows[hi];
    let t = (lambda_nm - l0) / (l1 - l0);
    Complex64::new(n0 + t * (n1 - n0), k0 + t * (k1 - k0))
}

/// The first row with λ > `lambda_nm` as [`interpolate`] finds it (tests).
#[cfg(test)]
fn first_row_above(rows: &[(f64, f64, f64)], lambda_nm: f64) -> usize {
    walk_to_row_above(rows, lambda_nm, guess_row_above(rows, lambda_nm))
}

/// Where to start looking for the first row with λ > `lambda_nm`
/// (`rows.partition_point(|r| r.0 <= lambda_nm)`). The metal tables are uniform in photon
/// energy, i.e. in 1/λ, so the row interpolated in 1/λ is the answer or next to it; walking
/// from it finds the same row as a binary search (rows ascend), in ~1 step instead of 6.
#[inline]
fn guess_row_above(rows: &[(f64, f64, f64)], lambda_nm: f64) -> usize {
    let n = rows.len();
    let (f, l) = (1.0 / rows[0].0, 1.0 / rows[n - 1].0);
    let t = (f - 1.0 / lambda_nm) / (f - l);
    // `as usize` saturates (NaN → 0).
    (t * (n - 1) as f64) as usize + 1
}

/// Walks from row `hi` to the first row with λ > `lambda_nm`, for
/// `rows[0].0 < lambda_nm < rows[last].0` (rows ascend); the clamp keeps the walks in bounds.
#[inline]
fn walk_to_row_above(rows: &[(f64, f64, f64)], lambda_nm: f64, hi: usize) -> usize {
    let n = rows.len();
    let mut hi = hi.clamp(1, n - 1);
    while hi > 1 && rows[hi - 1].0 > lambda_nm {
        hi -= 1;
    }
    while hi < n - 1 && rows[hi].0 <= lambda_nm {
        hi += 1;
    }
    hi
}

/// `n + ik` of a material at a hero sample's four wavelengths, as f32 (what the renderer's
/// Fresnel terms take): [`Material::nk`] bit for bit, with a table's interval found in a
/// uniform grid over λ built once per material. [`interpolate`]'s 1/λ row guess costs four
/// f64 divisions and its walks mispredict, all in one dependent chain per wavelength (7.5 %
/// of a gold teapot's render); here a wavelength's interval is two loads and a select, the
/// four wavelengths' chains have no branches between them and overlap, and only the
/// interpolation's own division is left (kept so that the values are [`Material::nk`]'s).
/// Formula models evaluate [`Material::nk`] as before.
#[derive(Debug, Clone)]
pub struct Nk4 {
    material: &'static Material,
    grid: Option<TableGrid>,
}

/// Row interval `i` of a table (rows i and i + 1): its ends and the rises of n and k over it
/// (the differences [`interpolate`] forms, so the same values).
#[derive(Debug, Clone, Copy)]
struct Interval {
    l0: f64,
    l1: f64,
    n0: f64,
    dn: f64,
    k0: f64,
    dk: f64,
}

/// One grid cell: λ below `split` lies in interval `below`, from `split` on in `below + 1`
/// (a cell no wider than half the narrowest interval holds at most one row).
#[derive(Debug, Clone, Copy)]
struct Cell {
    split: f64,
    below: u32,
}

#[derive(Debug, Clone)]
struct TableGrid {
    lo: f64,
    inv_width: f64,
    cells: Vec<Cell>,
    intervals: Vec<Interval>,
}

impl TableGrid {
    /// Cells no wider than half the narrowest row interval, at most 4096 (a table with
    /// equal neighbours, or finer than that, takes [`interpolate`]'s search where the cell
    /// answer is not the interval).
    fn new(rows: &[(f64, f64, f64)]) -> Self {
        let (lo, hi) = (rows[0].0, rows[rows.len() - 1].0);
        let narrowest = (rows.windows(2).map(|w| w[1].0 - w[0].0)).fold(hi - lo, f64::min);
        let n_cells = ((2.0 * (hi - lo) / narrowest).ceil() as usize).clamp(1, 4096);
        let inv_width = n_cells as f64 / (hi - lo);
        let last_interval = rows.len() - 2;
        let cells = (0..n_cells)
            .map(|c| {
                let edge = lo + c as f64 / inv_width;
                let below = (rows.partition_point(|r| r.0 <= edge).max(1) - 1).min(last_interval);
                let split = if below < last_interval {
                    rows[below + 1].0
                } else {
                    f64::INFINITY
                };
                Cell {
                    split,
                    below: below as u32,
                }
            })
            .collect();
        let intervals = (rows.windows(2))
            .map(|w| Interval {
                l0: w[0].0,
                l1: w[1].0,
                n0: w[0].1,
                dn: w[1].1 - w[0].1,
                k0: w[0].2,
                dk: w[1].2 - w[0].2,
            })
            .collect();
        TableGrid {
            lo,
            inv_width,
            cells,
            intervals,
        }
    }

    /// The interval [`interpolate`]'s search finds, where the cell's answer is not it (the
    /// cell's rounding at its edge, or a cell holding two rows); kept out of line so that
    /// its divisions are not hoisted into every lookup.
    #[cold]
    #[inline(never)]
    fn searched(&self, rows: &[(f64, f64, f64)], lambda_nm: f64) -> Interval {
        let hi = walk_to_row_above(rows, lambda_nm, guess_row_above(rows, lambda_nm));
        self.intervals[hi - 1]
    }

    /// [`interpolate`] at `lambda_nm`, without data-dependent branches where the cell's
    /// answer is the interval (always, for a table without equal neighbours).
    #[inline(always)]
    fn at(&self, rows: &[(f64, f64, f64)], lambda_nm: f64) -> (f64, f64) {
        let (first, last) = (rows[0], rows[rows.len() - 1]);
        // `as usize` saturates (NaN, below the start → 0).
        let c = (((lambda_nm - self.lo) * self.inv_width) as usize).min(self.cells.len() - 1);
        let cell = self.cells[c];
        // (+∞ would step past the last interval.)
        let i = (cell.below as usize + (lambda_nm >= cell.split) as usize)
            .min(self.intervals.len() - 1);
        let mut iv = self.intervals[i];
        let inside = (lambda_nm > first.0) & (lambda_nm < last.0);
        if inside & !((iv.l0 <= lambda_nm) & (lambda_nm < iv.l1)) {
            iv = self.searched(rows, lambda_nm);
        }
        let t = (lambda_nm - iv.l0) / (iv.l1 - iv.l0);
        let (mut n, mut k) = (iv.n0 + t * iv.dn, iv.k0 + t * iv.dk);
        // The ends and NaN as [`interpolate`] returns them (selects, not early exits).
        if lambda_nm >= last.0 {
            (n, k) = (last.1, last.2);
        }
        if lambda_nm <= first.0 {
            (n, k) = (first.1, first.2);
        }
        if lambda_nm.is_nan() {
            (n, k) = (f64::NAN, f64::NAN);
        }
        (n, k)
    }
}

impl Nk4 {
    /// The lookup of `material`.
    pub fn new(material: &'static Material) -> Self {
        let grid = match &material.model {
            Model::Table(rows) if rows.len() >= 2 => Some(TableGrid::new(rows)),
            _ => None,
        };
        Nk4 { material, grid }
    }

    /// (n, k) at the four wavelengths (nm): [`Material::nk`] rounded to f32.
    #[inline(always)]
    pub fn at(&self, lambda_nm: [f32; 4]) -> ([f32; 4], [f32; 4]) {
        match (&self.grid, &self.material.model) {
            (Some(grid), Model::Table(rows)) => {
                // Written out, so that the four chains interleave.
                let [a, b, c, d] = lambda_nm.map(|l| l as f64);
                let (a, b, c, d) = (
                    grid.at(rows, a),
                    grid.at(rows, b),
                    grid.at(rows, c),
                    grid.at(rows, d),
                );
                (
                    [a.0 as f32, b.0 as f32, c.0 as f32, d.0 as f32],
                    [a.1 as f32, b.1 as f32, c.1 as f32, d.1 as f32],
                )
            }
            _ => {
                let nk = lambda_nm.map(|l| self.material.nk(l as f64));
                (nk.map(|c| c.re as f32), nk.map(|c| c.im as f32))
            }
        }
    }
}

const DIELECTRICS: &str = include_str!("data/dielectrics.txt");
const METALS: &[(&str, &str, &str)] = &[
    ("Al", "aluminium,aluminum", include_str!("data/Al.csv")),
    ("Ag", "silver", include_str!("data/Ag.csv")),
    ("Au", "gold", include_str!("data/Au.csv")),
    ("Cu", "copper", include_str!("data/Cu.csv")),
];

fn parse_number(tok: &str) -> Result<f64, String> {
    let tok = tok.trim();
    if let Some(base) = tok.strip_suffix("^2") {
        let v: f64 = base.parse().map_err(|e| format!("'{tok}': {e}"))?;
        return Ok(v * v);
    }
    tok.parse().map_err(|e| format!("'{tok}': {e}"))
}

fn pairs(c: &[f64]) -> Vec<(f64, f64)> {
    c.chunks_exact(2).map(|p| (p[0], p[1])).collect()
}

fn parse_dielectrics(text: &'static str) -> Result<Vec<Material>, String> {
    let mut out = Vec::new();
    for (no, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        let ctx = |e: String| format!("data/dielectrics.txt line {}: {e}", no + 1);
        let f: Vec<&'static str> = line.split('|').map(str::trim).collect();
        if f.len() != 6 {
            return Err(ctx(format!("expected 6 '|' fields, got {}", f.len())));
        }
        let range: Vec<f64> = f[3]
            .split(',')
            .map(parse_number)
            .collect::<Result<_, _>>()
            .map_err(ctx)?;
        let c: Vec<f64> = f[4]
            .split(',')
            .map(parse_number)
            .collect::<Result<_, _>>()
            .map_err(ctx)?;
        if range.len() != 2 {
            return Err(ctx("range must be 'min,max'".into()));
        }
        let model = match f[2] {
            "sellmeier" | "poles" if c.len() % 2 == 1 => {
                let (a, terms) = (c[0], pairs(&c[1..]));
                if f[2] == "sellmeier" {
                    Model::Sellmeier { a, terms }
                } else {
                    Model::Poles { a, terms }
                }
            }
            "cauchy" if c.len() == 3 => Model::Cauchy {
                a: c[0],
                b: c[1],
                c: c[2],
            },
            m => return Err(ctx(format!("model '{m}' with {} coefficients", c.len()))),
        };
        out.push(Material {
            name: f[0],
            aliases: f[1]
                .split(',')
                .map(str::trim)
                .filter(|s| !s.is_empty())
                .collect(),
            source: f[5],
            valid_range_nm: (range[0], range[1]),
            model,
        });
    }
    Ok(out)
}

fn parse_metal(
    name: &'static str,
    aliases: &'static str,
    text: &'static str,
) -> Result<Material, String> {
    let mut rows = Vec::new();
    let mut header_seen = false;
    for (no, line) in text.lines().enumerate() {
        let line = line.trim();
        if line.is_empty() || line.starts_with('#') {
            continue;
        }
        if !header_seen {
            if line != "wavelength_nm,n,k" {
                return Err(format!(
                    "data/{name}.csv line {}: bad header '{line}'",
                    no + 1
                ));
            }
            header_seen = true;
            continue;
        }
        let v: Vec<f64> = line
            .split(',')
            .map(parse_number)
            .collect::<Result<_, _>>()
            .map_err(|e| format!("data/{name}.csv line {}: {e}", no + 1))?;
        if v.len() != 3 {
            return Err(format!(
                "data/{name}.csv line {}: expected 3 columns",
                no + 1
            ));
        }
        rows.push((v[0], v[1], v[2]));
    }
    if rows.len() < 2 || rows.windows(2).any(|w| w[1].0 <= w[0].0) {
        return Err(format!(
            "data/{name}.csv: need ≥ 2 rows with ascending wavelength"
        ));
    }
    Ok(Material {
        name,
        aliases: aliases.split(',').collect(),
        source: "Mitsuba 3 data/ior (luxpop.com database), see data file header",
        valid_range_nm: (rows[0].0, rows[rows.len() - 1].0),
        model: Model::Table(rows),
    })
}

fn build() -> Result<Vec<Material>, String> {
    let mut all = parse_dielectrics(DIELECTRICS)?;
    for &(name, aliases, text) in METALS {
        all.push(parse_metal(name, aliases, text)?);
    }
    Ok(all)
}

fn materials() -> &'static [Material] {
    static CELL: OnceLock<Vec<Material>> = OnceLock::new();
    // The data are compiled in and covered by `builtin_data_parses`; failing here means the
    // binary itself is broken, not the user's input.
    CELL.get_or_init(|| build().expect("built-in dispersion data must parse"))
}

/// Looks a material up by name or alias (case-insensitive).
pub fn lookup(name: &str) -> Option<&'static Material> {
    materials().iter().find(|m| m.is_called(name.trim()))
}

/// Names of all built-in materials.
pub fn names() -> Vec<&'static str> {
    materials().iter().map(|m| m.name).collect()
}

/// All built-in materials.
pub fn all() -> &'static [Material] {
    materials()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn builtin_data_parses() {
        let all = build().unwrap();
        for want in [
            "MgF2", "ZnS", "SiO2", "TiO2", "water", "PET", "BK7", "Al", "Ag", "Au", "Cu",
        ] {
            assert!(all.iter().any(|m| m.name == want), "{want} missing");
        }
        // Every material finite and physical over the visible range 360–830 nm.
        for m in &all {
            for l in 360..=830 {
                let v = m.nk(l as f64);
                assert!(
                    v.re.is_finite() && v.re > 0.0 && v.im >= 0.0,
                    "{} at {l}: {v}",
                    m.name
                );
            }
        }
    }

    /// `nk_lanes` is `nk` bit for bit for every built-in material (formulas and tables), at
    /// wavelengths inside and beyond the visible range, poles of the formulas included, and
    /// NaN.
    #[test]
    fn nk_lanes_is_nk() {
        let same = |a: Complex64, b: Complex64| {
            let bits = |x: f64| if x.is_nan() { u64::MAX } else { x.to_bits() };
            bits(a.re) == bits(b.re) && bits(a.im) == bits(b.im)
        };
        let mut probes: Vec<f64> = (0..=300).map(|k| 200.0 + 3.1 * k as f64).collect();
        probes.extend([1e-3, 0.0, 5e4, f64::NAN, f64::INFINITY]);
        for m in all() {
            if let Model::Sellmeier { terms, .. } | Model::Poles { terms, .. } = &m.model {
                // λ² = c exactly where a term's denominator vanishes.
                probes.extend(terms.iter().map(|&(_, c)| c.max(0.0).sqrt() * 1e3));
            }
        }
        for m in all() {
            for lanes in probes.chunks(4).filter(|c| c.len() == 4) {
                let got = m.nk_lanes([lanes[0], lanes[1], lanes[2], lanes[3]]);
                for (k, &l) in lanes.iter().enumerate() {
                    assert!(
                        same(got[k], m.nk(l)),
                        "{} at {l}: {} vs {}",
                        m.name,
                        got[k],
                        m.nk(l)
                    );
                }
            }
            assert!(same(m.nk_lanes([550.0])[0], m.nk(550.0)));
        }
    }

    /// Published reference values (refractiveindex.info pages of the cited sources).
    #[test]
    fn reference_values() {
        let n = |name: &str, l: f64| lookup(name).unwrap().nk(l).re;
        let close = |a: f64, b: f64, tol: f64| assert!((a - b).abs() < tol, "{a} vs {b}");
        close(n("SiO2", 587.6), 1.4585, 1e-4); // fused silica n_d
        close(n("BK7", 587.6), 1.5168, 1e-4); // N-BK7 n_d
        close(n("water", 589.3), 1.3333, 2e-4); // water 20 °C
        close(n("MgF2", 550.0), 1.3790, 1e-3); // MgF2 n_o
        close(n("ZnS", 550.0), 2.386, 5e-3);
        close(n("TiO2", 550.0), 2.648, 5e-3); // rutile n_o
        close(n("PET", 632.8), 1.6357, 1e-4);
        close(n("PET", 589.0), 1.640, 1e-3);
        // A table row is returned exactly; between rows it interpolates.
        let au = lookup("gold").unwrap();
        assert_eq!(au.nk(298.757050), Complex64::new(1.795, 1.920375));
        assert!(lookup("AU").is_some() && lookup("fused_silica").is_some());
        assert!(lookup("unobtainium").is_none());
    }

    #[test]
    fn row_search_is_the_binary_search() {
        let all = build().unwrap();
        let tables: Vec<&[(f64, f64, f64)]> = (all.iter())
            .filter_map(|m| match &m.model {
                Model::Table(rows) => Some(rows.as_slice()),
                _ => None,
            })
            .collect();
        // Made-up tables too: uneven in 1/λ, and with equal neighbours.
        let uneven = [
            (300.0, 1.0, 0.0),
            (301.0, 2.0, 0.0),
            (700.0, 3.0, 0.0),
            (900.0, 4.0, 0.0),
        ];
        let ties = [
            (400.0, 1.0, 0.0),
            (500.0, 2.0, 0.0),
            (500.0, 3.0, 0.0),
            (600.0, 4.0, 0.0),
        ];
        assert!(tables.len() >= 4);
        for rows in tables.into_iter().chain([&uneven[..], &ties[..]]) {
            let (lo, hi) = (rows[0].0, rows[rows.len() - 1].0);
            // Every row, its neighbours in f64 and a dense sweep between the ends.
            let mut probes: Vec<f64> = (rows.iter())
                .flat_map(|r| [r.0, r.0.next_down(), r.0.next_up()])
                .collect();
            probes.extend((0..=5000).map(|k| lo + (hi - lo) * k as f64 / 5000.0));
            for l in probes.into_iter().filter(|&l| l > lo && l < hi) {
                let want = rows.partition_point(|r| r.0 <= l);
                assert_eq!(first_row_above(rows, l), want, "λ = {l}");
            }
        }
    }

    /// The grid lookup gives `nk` rounded to f32, bit for bit: every built-in material (tables
    /// and formulas) and made-up tables (uneven, equal neighbours, two rows), at every row, its
    /// f32 neighbours, a dense sweep, the ends, beyond them, and non-finite wavelengths.
    #[test]
    fn four_lane_lookup_is_nk() {
        let table = |rows: &[(f64, f64, f64)]| -> &'static Material {
            Box::leak(Box::new(Material {
                name: "test",
                aliases: Vec::new(),
                source: "test",
                valid_range_nm: (rows[0].0, rows[rows.len() - 1].0),
                model: Model::Table(rows.to_vec()),
            }))
        };
        let made_up = [
            table(&[
                (300.0, 1.0, 0.5),
                (301.0, 2.0, 0.1),
                (700.0, 3.0, 0.0),
                (900.0, 4.0, 2.0),
            ]),
            table(&[
                (400.0, 1.0, 0.0),
                (500.0, 2.0, 1.0),
                (500.0, 3.0, 7.0),
                (600.0, 4.0, 0.0),
            ]),
            table(&[(450.5, 1.5, 0.25), (451.25, 0.5, 4.0)]),
        ];
        let mut checked_tables = 0;
        for m in all().iter().chain(made_up) {
            let mut probes: Vec<f32> =
                vec![f32::NAN, f32::INFINITY, -f32::INFINITY, 0.0, -5.0, 1e9];
            probes.extend((0..=20_000).map(|k| 250.0 + 700.0 * k as f32 / 20_000.0));
            if let Model::Table(rows) = &m.model {
                checked_tables += 1;
                for r in rows {
                    let l = r.0 as f32;
                    probes.extend([l, l.next_down(), l.next_up(), l.next_down().next_down()]);
                }
            }
            let lookup = Nk4::new(m);
            for chunk in probes.chunks(4) {
                let mut lambda = [550.0; 4];
                lambda[..chunk.len()].copy_from_slice(chunk);
                let (n, k) = lookup.at(lambda);
                for i in 0..4 {
                    let want = m.nk(lambda[i] as f64);
                    let same = |a: f32, b: f64| a.to_bits() == (b as f32).to_bits();
                    assert!(
                        same(n[i], want.re) && same(k[i], want.im),
                        "{} at {}: {} {} vs {want}",
                        m.name,
                        lambda[i],
                        n[i],
                        k[i]
                    );
                }
            }
        }
        assert!(checked_tables >= 7);
    }

    #[test]
    fn metals_look_like_metals() {
        // Gold and copper: low n, high k in the red; silver: n ≪ 1 in the visible.
        let au = lookup("Au").unwrap().nk(650.0);
        assert!(au.re < 0.3 && au.im > 3.0, "{au}");
        let ag = lookup("Ag").unwrap().nk(550.0);
        assert!(ag.re < 0.2 && ag.im > 3.0, "{ag}");
        let al = lookup("Al").unwrap().nk(550.0);
        assert!(al.im > 6.0, "{al}");
    }
}
