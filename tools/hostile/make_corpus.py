#!/usr/bin/env python3
"""Writes the hostile-input corpus: malformed, truncated, huge, NaN, cyclic and garbage inputs
for every file format and command-line option thinfilm reads, plus the manifest that says how
to run each one and what its error message must name.

    python3 tools/hostile/make_corpus.py            # rewrites tests/hostile/

Needs only the Python standard library (the files are written byte by byte, so the corpus is
the same on every machine). The manifest `tests/hostile/cases.txt` has one case per line:

    ID <TAB> EXPECT <TAB> ARGS

- ARGS: the `thinfilm` arguments; `{C}` is the corpus directory (a scratch copy of
  tests/hostile/corpus), `{O}` a fresh scratch directory for outputs.
- EXPECT: `fail:TEXT|TEXT…` — the run must exit with status 1 (an error, not a panic or a
  signal) and its stderr must contain every TEXT (case-insensitive): the file, key, line or
  option at fault. `ok` — the input is odd but legal and must succeed.

Lines starting with `@sparse PATH BYTES` (PATH relative to the corpus) ask the runner to create
a sparse file of that length before the cases run: inputs that declare gigabytes without
occupying them.

Run the corpus with `tools/hostile/run.sh` (20 s and 2 GiB per case) or `cargo test --release
--test hostile` (the same cases, in CI).
"""

import base64
import json
import os
import shutil
import struct
import zlib

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
OUT = os.path.join(ROOT, "tests", "hostile")
C = os.path.join(OUT, "corpus")
shutil.rmtree(C, ignore_errors=True)

cases = []  # (id, expect, args)
sparse = []  # (path, bytes)


def case(cid, expect, args):
    assert all(c[0] != cid for c in cases), cid
    assert "\t" not in args
    cases.append((cid, expect, args))


def write(rel, data):
    path = os.path.join(C, rel)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    if isinstance(data, str):
        data = data.encode()
    with open(path, "wb") as f:
        f.write(data)
    return rel


# ------------------------------------------------------------------------------------ ENVI

W, H, B = 4, 3, 8
WAVES = [400 + 40 * i for i in range(B)]


def envi_header(**over):
    fields = {
        "samples": W,
        "lines": H,
        "bands": B,
        "header offset": 0,
        "data type": 4,
        "interleave": "bsq",
        "byte order": 0,
        "wavelength units": "Nanometers",
        "wavelength": "{" + ", ".join(str(w) for w in WAVES) + "}",
        "fwhm": "{" + ", ".join("4" for _ in WAVES) + "}",
    }
    for k, v in over.items():
        k = k.replace("_", " ")
        if v is None:
            fields.pop(k, None)
        else:
            fields[k] = v
    return "ENVI\n" + "".join(f"{k} = {v}\n" for k, v in fields.items())


def cube_bytes(n=W * H * B, seed=1):
    # Deterministic reflectance-like values in [0.02, 0.3].
    out = bytearray()
    x = seed
    for _ in range(n):
        x = (x * 1103515245 + 12345) % (1 << 31)
        out += struct.pack("<f", 0.02 + 0.28 * x / (1 << 31))
    return bytes(out)


def capture_json(angles, **over):
    doc = {
        "format": "thinfilm-capture/1",
        "polarization": "s",
        "ambient_ior": 1.0,
        "substrate": {"ior": 1.64, "k": 0.0},
        "angles": [{"incident_deg": a, "cube": c} for a, c in angles],
    }
    for k, v in over.items():
        if v is None:
            doc.pop(k, None)
        else:
            doc[k] = v
    return json.dumps(doc, indent=1)


def good_capture(rel_dir):
    """A valid 3-angle capture in rel_dir; returns the cube names."""
    names = []
    for i, a in enumerate([10, 30, 50]):
        write(f"{rel_dir}/t{a}.hdr", envi_header())
        write(f"{rel_dir}/t{a}.img", cube_bytes(seed=i + 1))
        names.append((a, f"t{a}.hdr"))
    write(f"{rel_dir}/capture.json", capture_json(names))
    return names


good_capture("capture_ok")
case("capture_ok", "ok", "estimate {C}/capture_ok --out {O}/fit --quiet")


def envi_case(cid, header, expect, binary=None, img_name="c.img"):
    """A one-angle capture whose cube has the given header text (and binary)."""
    d = f"envi/{cid}"
    write(f"{d}/c.hdr", header)
    if binary is not False:
        write(f"{d}/{img_name}", cube_bytes() if binary is None else binary)
    write(f"{d}/capture.json", capture_json([(20, "c.hdr")]))
    case(f"envi_{cid}", expect, f"estimate {{C}}/{d} --out {{O}}/fit --film-ior 1.4 --quiet")


envi_case("offset_2_64", envi_header(header_offset=2**64 - 8), "fail:c.hdr|header offset")
envi_case("offset_near_usize", envi_header(header_offset=2**63), "fail:c.hdr|header offset")
envi_case("offset_past_end", envi_header(header_offset=10**6), "fail:c.img|truncated")
envi_case("offset_negative", envi_header(header_offset=-4), "fail:c.hdr|header offset")
envi_case("dims_wrap_to_zero", envi_header(samples=2**32, lines=2**32, bands=1,
          wavelength="{500}", fwhm="{4}"), "fail:c.hdr|samples")
envi_case("bytes_wrap_to_zero", envi_header(samples=2**62, lines=1, bands=1,
          wavelength="{500}", fwhm="{4}"), "fail:c.hdr|samples")
envi_case("dims_overflow_u64", envi_header(samples=2**64 + 5), "fail:c.hdr|samples")
envi_case("dims_huge_truncated", envi_header(samples=100000, lines=100000), "fail:c.img|truncated")
envi_case("dims_huge_sparse", envi_header(samples=40000, lines=40000, bands=8),
          "fail:c.hdr|memory limit", binary=b"")
sparse.append(("envi/dims_huge_sparse/c.img", 40000 * 40000 * 8 * 4))
envi_case("samples_negative", envi_header(samples=-1), "fail:c.hdr|samples")
envi_case("samples_float", envi_header(samples="4.5"), "fail:c.hdr|samples")
envi_case("samples_text", envi_header(samples="four"), "fail:c.hdr|samples")
envi_case("samples_missing", envi_header(samples=None), "fail:c.hdr|samples")
envi_case("bands_zero", envi_header(bands=0), "fail:c.hdr|bands")
envi_case("lines_zero", envi_header(lines=0), "fail:c.hdr|lines")
envi_case("data_type_complex", envi_header(data_type=6), "fail:c.hdr|data type")
envi_case("data_type_99", envi_header(data_type=99), "fail:c.hdr|data type")
envi_case("data_type_huge", envi_header(data_type=2**40 + 4), "fail:c.hdr|data type")
envi_case("byte_order_2", envi_header(byte_order=2), "fail:c.hdr|byte order")
envi_case("interleave_xyz", envi_header(interleave="xyz"), "fail:c.hdr|interleave")
envi_case("wavelength_count", envi_header(wavelength="{400, 500}"), "fail:c.hdr|wavelength")
envi_case("wavelength_nan", envi_header(wavelength="{" + ", ".join(["nan"] * B) + "}"),
          "fail:c.hdr|wavelength")
envi_case("wavelength_inf", envi_header(wavelength="{" + ", ".join(["inf"] * B) + "}"),
          "fail:c.hdr|wavelength")
envi_case("wavelength_negative", envi_header(wavelength="{" + ", ".join(str(-w) for w in WAVES) + "}"),
          "fail:c.hdr|wavelength")
envi_case("wavelength_duplicate", envi_header(wavelength="{" + ", ".join(["500"] * B) + "}"),
          "fail:c.hdr|wavelength")
envi_case("wavelength_huge", envi_header(wavelength="{" + ", ".join(["1e300"] * B) + "}"),
          "fail:c.hdr|wavelength")
envi_case("wavelength_units", envi_header(wavelength_units="parsecs"), "fail:c.hdr|wavelength units")
envi_case("wavelength_missing", envi_header(wavelength=None), "fail:c.hdr|wavelength")
envi_case("fwhm_negative", envi_header(fwhm="{" + ", ".join(["-4"] * B) + "}"), "fail:c.hdr|fwhm")
envi_case("fwhm_nan", envi_header(fwhm="{" + ", ".join(["nan"] * B) + "}"), "fail:c.hdr|fwhm")
envi_case("fwhm_huge", envi_header(fwhm="{" + ", ".join(["1e300"] * B) + "}"), "fail:c.hdr|fwhm")
envi_case("brace_unclosed", envi_header(wavelength="{400, 440"), "fail:c.hdr|wavelength")
envi_case("brace_unclosed_at_end", envi_header() + "description = {never closed\n", "fail:c.hdr|never closes")
envi_case("not_envi", "HELLO\nsamples = 4\n", "fail:c.hdr|not an ENVI header")
envi_case("empty_header", "", "fail:c.hdr|not an ENVI header")
envi_case("binary_garbage_header", bytes(range(256)) * 4, "fail:c.hdr|ENVI")
envi_case("nul_in_header", envi_header().replace("samples = 4", "samples = 4\0"), "fail:c.hdr|samples")
envi_case("ignore_value_text", envi_header(data_ignore_value="none"), "fail:c.hdr|data ignore value")
envi_case("no_binary", envi_header(), "fail:c.hdr|no binary data file", binary=False)
envi_case("binary_truncated", envi_header(), "fail:c.img|truncated", binary=cube_bytes()[:50])
envi_case("line_without_equals", envi_header() + "this line has no equals sign\n", "fail:c.hdr|key = value")
envi_case("all_nan_data", envi_header(), "fail:capture.json|no usable sample",
          binary=struct.pack("<f", float("nan")) * (W * H * B))
envi_case("bands_million", envi_header(samples=1, lines=1, bands=10**6,
          wavelength=None, fwhm=None), "fail:c.hdr|wavelength", binary=b"")
sparse.append(("envi/bands_million/c.img", 4 * 10**6))
# More bands than any spectrometer has, with a matching wavelength list.
envi_case("bands_5000", envi_header(samples=1, lines=1, bands=5000,
          wavelength="{" + ",".join(str(400 + i * 0.05) for i in range(5000)) + "}", fwhm=None),
          "ok", binary=b"")
sparse.append(("envi/bands_5000/c.img", 4 * 5000))

# ------------------------------------------------------------------------------ capture.json


def capture_case(cid, text, expect, extra=""):
    d = f"capture/{cid}"
    write(f"{d}/capture.json", text)
    case(f"capture_{cid}", expect, f"estimate {{C}}/{d} --out {{O}}/fit --quiet {extra}".strip())


OK_ANGLES = [(10, "../../capture_ok/t10.hdr"), (30, "../../capture_ok/t30.hdr"),
             (50, "../../capture_ok/t50.hdr")]
capture_case("not_json", "{ this is not json", "fail:capture.json|JSON")
capture_case("empty", "", "fail:capture.json")
capture_case("binary", bytes(range(256)), "fail:capture.json")
capture_case("array", "[1, 2, 3]", "fail:capture.json")
capture_case("deep_nesting", "[" * 20000 + "]" * 20000, "fail:capture.json")
capture_case("truncated", capture_json(OK_ANGLES)[:120], "fail:capture.json")
capture_case("format_wrong", capture_json(OK_ANGLES, format="thinfilm-capture/9"), "fail:capture.json|format")
capture_case("polarization_bad", capture_json(OK_ANGLES, polarization="q"), "fail:capture.json|polarization")
capture_case("polarization_number", capture_json(OK_ANGLES, polarization=5), "fail:capture.json|polarization")
capture_case("ambient_1e26", capture_json(OK_ANGLES, ambient_ior=1e26), "fail:capture.json|ambient_ior")
capture_case("ambient_65535", capture_json(OK_ANGLES, ambient_ior=65535), "fail:capture.json|ambient_ior")
capture_case("ambient_zero", capture_json(OK_ANGLES, ambient_ior=0), "fail:capture.json|ambient_ior")
capture_case("ambient_negative", capture_json(OK_ANGLES, ambient_ior=-1.0), "fail:capture.json|ambient_ior")
capture_case("ambient_nan_string", capture_json(OK_ANGLES, ambient_ior="NaN"), "fail:capture.json|ambient_ior")
capture_case("ambient_complex", capture_json(OK_ANGLES, ambient_ior="1.0+0.5i"), "fail:capture.json|ambient_ior")
capture_case("ambient_bool", capture_json(OK_ANGLES, ambient_ior=True), "fail:capture.json|ambient_ior")
capture_case("ambient_1e400", capture_json(OK_ANGLES).replace('"ambient_ior": 1.0', '"ambient_ior": 1e400'),
             "fail:capture.json")
capture_case("substrate_huge", capture_json(OK_ANGLES, substrate=1e300), "fail:capture.json|substrate")
capture_case("substrate_negative", capture_json(OK_ANGLES, substrate=-1.5), "fail:capture.json|substrate")
capture_case("substrate_k_nan", capture_json(OK_ANGLES, substrate={"ior": 1.5, "k": "nan"}),
             "fail:capture.json|substrate")
capture_case("substrate_k_huge", capture_json(OK_ANGLES, substrate={"ior": 1.5, "k": 1e300}),
             "fail:capture.json|substrate")
capture_case("substrate_inf_string", capture_json(OK_ANGLES, substrate="inf"), "fail:capture.json|substrate")
capture_case("substrate_unknown", capture_json(OK_ANGLES, substrate={"material": "unobtainium"}),
             "fail:capture.json|substrate")
capture_case("substrate_missing", capture_json(OK_ANGLES, substrate=None), "fail:capture.json|substrate")
capture_case("angles_empty", capture_json([]), "fail:capture.json|angles")
capture_case("angles_duplicate", capture_json([OK_ANGLES[0], OK_ANGLES[0], OK_ANGLES[1]]),
             "fail:capture.json|incident_deg")
capture_case("angles_duplicate_value", capture_json([(10, OK_ANGLES[0][1]), (10, OK_ANGLES[1][1])]),
             "fail:capture.json|angles[1]")
capture_case("angle_90", capture_json([(90, OK_ANGLES[0][1])]), "fail:capture.json|angles[0]")
capture_case("angle_negative", capture_json([(-5, OK_ANGLES[0][1])]), "fail:capture.json|angles[0]")
capture_case("angle_huge", capture_json([(1e308, OK_ANGLES[0][1])]), "fail:capture.json|angles[0]")
capture_case("angle_string", capture_json(OK_ANGLES).replace('"incident_deg": 10', '"incident_deg": "ten"'),
             "fail:capture.json|line")
capture_case("angles_many", json.dumps(json.loads(capture_json([(i * 0.01, OK_ANGLES[0][1]) for i in range(1001)]))),
             "fail:capture.json|angles")
capture_case("cube_missing", capture_json([(10, "nope.hdr")]), "fail:capture.json|nope.hdr")
capture_case("cube_empty_name", capture_json([(10, "")]), "fail:capture.json|angles[0].cube")
capture_case("cube_is_dir", capture_json([(10, ".")]), "fail:capture.json|angles[0].cube")
capture_case("cube_not_envi", capture_json([(10, "capture.json")]), "fail:capture.json|angles[0].cube")
capture_case("unknown_field", capture_json(OK_ANGLES, exposure=3), "fail:capture.json|exposure")
capture_case("white_without_match", capture_json(OK_ANGLES).replace(
    '"cube": "../../capture_ok/t10.hdr"',
    '"cube": "../../capture_ok/t10.hdr", "white": "../../envi/bands_zero/c.hdr"'),
    "fail:capture.json|angles[0].white")
capture_case("dark_without_white", capture_json(OK_ANGLES).replace(
    '"cube": "../../capture_ok/t10.hdr"', '"cube": "../../capture_ok/t10.hdr", "dark": "../../capture_ok/t10.hdr"'),
    "fail:capture.json|dark")
write("capture/size_mismatch/small.hdr", envi_header(samples=2, lines=2))
write("capture/size_mismatch/small.img", cube_bytes(2 * 2 * B))
capture_case("size_mismatch", capture_json([OK_ANGLES[0], (40, "small.hdr")]), "fail:capture.json|small.hdr")
capture_case("capture_missing_dir", "{}", "fail:capture.json")
case("capture_no_such_dir", "fail:nonexistent", "estimate {C}/capture/nonexistent --out {O}/fit")

# ----------------------------------------------------------------------------- estimate CLI

EST = "estimate {C}/capture_ok --out {O}/fit --quiet"
for cid, opt, culprit in [
    ("stride_zero", "--method grid --grid-pixel-stride 0", "--grid-pixel-stride"),
    ("max_thickness_nan", "--max-thickness-nm nan", "--max-thickness-nm"),
    ("max_thickness_huge", "--max-thickness-nm 1e300", "--max-thickness-nm"),
    ("min_thickness_negative", "--min-thickness-nm -5", "--min-thickness-nm"),
    ("thickness_inverted", "--min-thickness-nm 900 --max-thickness-nm 100", "--min-thickness-nm"),
    ("film_ior_nan", "--film-ior nan", "--film-ior"),
    ("film_ior_zero", "--film-ior 0", "--film-ior"),
    ("film_ior_huge", "--film-ior 1e26", "--film-ior"),
    ("min_film_ior_inf", "--min-film-ior inf", "--min-film-ior"),
    ("film_ior_range_inverted", "--min-film-ior 2.5 --max-film-ior 1.2", "--min-film-ior"),
    ("grid_ior_step_tiny", "--method grid --grid-ior-step 1e-12", "--grid-ior-step"),
    ("grid_step_nan", "--method grid --grid-thickness-step-nm nan", "--grid-thickness-step-nm"),
    ("grid_step_tiny", "--method grid --grid-thickness-step-nm 1e-9", "--grid-thickness-step-nm"),
]:
    case(f"estimate_{cid}", f"fail:{culprit}", f"{EST} {opt}")
write("not_a_dir", "plain file\n")
case("estimate_out_is_file", "fail:not_a_dir", "estimate {C}/capture_ok --out {C}/not_a_dir --quiet")
write("gt/bad_json/ground_truth.json", "{ nope")
case("estimate_ground_truth_bad", "fail:ground_truth.json",
     f"{EST} --ground-truth {{C}}/gt/bad_json")
write("gt/huge/ground_truth.json", json.dumps({
    "format": "thinfilm-ground-truth/1", "film": 1.37, "substrate": 1.64,
    "width": 2**62, "height": 2**62, "thickness_exr": "t.exr"}))
case("estimate_ground_truth_missing_exr", "fail:t.exr", f"{EST} --ground-truth {{C}}/gt/huge")

# ----------------------------------------------------------------------------- simulate CLI

SIM = "simulate --out {O}/sim --size 8x6"
for cid, opt, culprit in [
    ("size_huge", "--size 200000x200000", "--size"),
    ("size_overflow", "--size 99999999999999999999x2", "--size"),
    ("size_zero", "--size 0x5", "--size"),
    ("size_bands_budget", "--size 20000x20000 --wavelengths 400:720:1", "--size"),
    ("wavelengths_tiny_step", "--wavelengths 400:720:0.00001", "--wavelengths"),
    ("wavelengths_many", "--wavelengths 400:720:0.01", "wavelengths"),
    ("thickness_max_allowed_plus", "--thickness 20001", "--thickness"),
    ("wavelengths_nan", "--wavelengths nan:700:4", "--wavelengths"),
    ("wavelengths_dup", "--wavelengths 500,500,600", "--wavelengths"),
    ("thickness_nan", "--thickness nan", "--thickness"),
    ("thickness_huge", "--thickness 1e300", "--thickness"),
    ("angles_nan", "--angles nan", "--angles"),
    ("angles_dup", "--angles 10,10,20", "angle"),
    ("ambient_huge", "--ambient-ior 1e26", "--ambient-ior"),
    ("ambient_nan", "--ambient-ior nan", "--ambient-ior"),
    ("film_ior_huge", "--film-ior 1e26", "--film-ior"),
    ("fwhm_huge", "--fwhm 1e300", "fwhm"),
    ("noise_inf", "--noise inf", "--noise"),
    ("white_counts_nan", "--raw-counts --white-counts nan", "--white-counts"),
    ("read_noise_huge", "--raw-counts --read-noise 1e300", "read noise"),
    ("interleave_bad", "--interleave zzz", "--interleave"),
]:
    case(f"simulate_{cid}", f"fail:{culprit}", f"{SIM} {opt}")

# --------------------------------------------------------------------------- reflectance CLI

for cid, opt, culprit in [
    ("thickness_nan", "--film-ior 1.37 --thickness nan", "--thickness"),
    ("wavelengths_tiny", "--film-ior 1.37 --thickness 100 --wavelengths 380:780:1e-9", "--wavelengths"),
    ("angle_90", "--film-ior 1.37 --thickness 100 --angle 90", "--angle"),
    ("layer_nan", "--layer MgF2:nan", "--layer"),
    ("layers_many", "--layer (MgF2:1)x1000", "--layer"),
    ("film_ior_inf", "--film-ior inf --thickness 100", "--film-ior"),
]:
    case(f"reflectance_{cid}", f"fail:{culprit}", f"reflectance {opt}")

# ------------------------------------------------------------------------------ scenes: XML

SCENE_HEAD = '<scene version="3.0.0">\n'
SENSOR = """<sensor type="perspective"><float name="fov" value="40"/>
<transform name="to_world"><lookat origin="0,0,5" target="0,0,0" up="0,1,0"/></transform>
<sampler type="independent"><integer name="sample_count" value="1"/></sampler>
<film type="hdrfilm"><integer name="width" value="8"/><integer name="height" value="8"/></film>
</sensor>
"""


def xml_scene(body, sensor=SENSOR):
    return SCENE_HEAD + sensor + body + "</scene>\n"


def xml_case(cid, text, expect, extra=""):
    rel = write(f"xml/{cid}.xml", text)
    case(f"xml_{cid}", expect, f"render {{C}}/{rel} -o {{O}}/out.exr {extra}".strip())


SPHERE = '<shape type="sphere"><float name="radius" value="1"/></shape>\n'
xml_case("ok_sphere", xml_scene(SPHERE), "ok")
xml_case("malformed", "<scene version='3.0.0'><shape", "fail:malformed.xml")
xml_case("empty", "", "fail:empty.xml")
xml_case("binary", bytes(range(256)) * 8, "fail:binary.xml")
xml_case("wrong_root", "<mesh/>", "fail:wrong_root.xml|<scene")
xml_case("no_version", "<scene></scene>", "fail:no_version.xml|version")
xml_case("deep_nesting", SCENE_HEAD + "<bsdf type='x'>" * 2000 + "</bsdf>" * 2000 + "</scene>",
         "fail:deep_nesting.xml")
xml_case("deep_nesting_200", SCENE_HEAD + "<bsdf type='twosided' id='a'>" + "<bsdf type='twosided'>" * 200
         + "</bsdf>" * 200 + "</bsdf></scene>", "fail:deep_nesting_200.xml")
xml_case("billion_laughs", """<?xml version="1.0"?>
<!DOCTYPE scene [
<!ENTITY a "aaaaaaaaaa">
<!ENTITY b "&a;&a;&a;&a;&a;&a;&a;&a;&a;&a;">
<!ENTITY c "&b;&b;&b;&b;&b;&b;&b;&b;&b;&b;">
<!ENTITY d "&c;&c;&c;&c;&c;&c;&c;&c;&c;&c;">
<!ENTITY e "&d;&d;&d;&d;&d;&d;&d;&d;&d;&d;">
<!ENTITY f "&e;&e;&e;&e;&e;&e;&e;&e;&e;&e;">
<!ENTITY g "&f;&f;&f;&f;&f;&f;&f;&f;&f;&f;">
<!ENTITY h "&g;&g;&g;&g;&g;&g;&g;&g;&g;&g;">
<!ENTITY i "&h;&h;&h;&h;&h;&h;&h;&h;&h;&h;">
]>
<scene version="3.0.0"><string name="x" id="x" value="&i;"/></scene>
""", "fail:billion_laughs.xml")
for cid, body, culprit in [
    ("radius_nan", '<shape type="sphere"><float name="radius" value="nan"/></shape>', "radius"),
    ("radius_negative", '<shape type="sphere"><float name="radius" value="-1"/></shape>', "radius"),
    ("radius_f32_overflow", '<shape type="sphere"><float name="radius" value="1e39"/></shape>', "radius"),
    ("rgb_nan", '<shape type="sphere"><bsdf type="diffuse"><rgb name="reflectance" value="nan, 0, 0"/></bsdf></shape>', "reflectance"),
    ("rgb_f32_overflow", '<shape type="sphere"><bsdf type="diffuse"><rgb name="reflectance" value="1e39"/></bsdf></shape>', "reflectance"),
    ("reflectance_float_nan", '<shape type="sphere"><bsdf type="diffuse"><float name="reflectance" value="nan"/></bsdf></shape>', "reflectance"),
    ("reflectance_negative", '<shape type="sphere"><bsdf type="diffuse"><float name="reflectance" value="-2"/></bsdf></shape>', "reflectance"),
    ("spectrum_nan", '<shape type="sphere"><bsdf type="diffuse"><spectrum name="reflectance" value="400:nan, 700:0.5"/></bsdf></shape>', "reflectance"),
    ("spectrum_huge", '<shape type="sphere"><bsdf type="diffuse"><spectrum name="reflectance" value="1e300"/></bsdf></shape>', "reflectance"),
    ("radiance_inf", '<emitter type="constant"><float name="radiance" value="inf"/></emitter>', "radiance"),
    ("radiance_negative", '<emitter type="constant"><rgb name="radiance" value="-1, 1, 1"/></emitter>', "radiance"),
    ("d65_scale_nan", '<emitter type="constant"><spectrum name="radiance" type="d65"><float name="scale" value="nan"/></spectrum></emitter>', "scale"),
    ("thickness_nan", '<shape type="sphere"><bsdf type="thinfilm"><float name="thickness" value="nan"/></bsdf></shape>', "thickness"),
    ("thickness_huge", '<shape type="sphere"><bsdf type="thinfilm"><float name="thickness" value="1e300"/></bsdf></shape>', "thickness"),
    ("film_ior_huge", '<shape type="sphere"><bsdf type="thinfilm"><float name="film_ior" value="1e300"/></bsdf></shape>', "film_ior"),
    ("alpha_nan", '<shape type="sphere"><bsdf type="roughconductor"><float name="alpha" value="nan"/></bsdf></shape>', "alpha"),
    ("alpha_huge", '<shape type="sphere"><bsdf type="roughplastic"><float name="alpha" value="1e30"/></bsdf></shape>', "alpha"),
    ("int_ior_inf", '<shape type="sphere"><bsdf type="dielectric"><float name="int_ior" value="inf"/></bsdf></shape>', "int_ior"),
    ("int_ior_huge", '<shape type="sphere"><bsdf type="dielectric"><float name="int_ior" value="1e30"/></bsdf></shape>', "int_ior"),
    ("eta_nan", '<shape type="sphere"><bsdf type="conductor"><float name="eta" value="nan"/></bsdf></shape>', "eta"),
    ("theta_inf", '<shape type="sphere"><bsdf type="polarizer"><float name="theta" value="inf"/></bsdf></shape>', "theta"),
    ("layers_explosion", '<shape type="sphere"><bsdf type="thinfilm"><string name="layers" value="((((((MgF2:1)x1000)x1000)x1000)x1000)x1000)"/></bsdf></shape>', "layers"),
    ("layers_nested_groups", '<shape type="sphere"><bsdf type="thinfilm"><string name="layers" value="((((MgF2:1)x1000)x1000)x1000)"/></bsdf></shape>', "layers"),
    ("layer_thickness_nan", '<shape type="sphere"><bsdf type="thinfilm"><string name="layers" value="MgF2:nan"/></bsdf></shape>', "layers"),
    ("layer_ior_nan", '<shape type="sphere"><bsdf type="thinfilm"><string name="layers" value="nan:100"/></bsdf></shape>', "layers"),
    ("translate_nan", '<shape type="sphere"><transform name="to_world"><translate x="nan"/></transform></shape>', "translate"),
    ("scale_zero", '<shape type="rectangle"><transform name="to_world"><scale value="0"/></transform></shape>', "scale"),
    ("scale_inf", '<shape type="rectangle"><transform name="to_world"><scale value="1e39"/></transform></shape>', "scale"),
    ("matrix_nan", '<shape type="rectangle"><transform name="to_world"><matrix value="nan 0 0 0 0 1 0 0 0 0 1 0 0 0 0 1"/></transform></shape>', "matrix"),
    ("matrix_singular", '<shape type="rectangle"><transform name="to_world"><matrix value="0 0 0 0 0 0 0 0 0 0 0 0 0 0 0 1"/></transform></shape>', "matrix"),
    ("rotate_angle_inf", '<shape type="rectangle"><transform name="to_world"><rotate y="1" angle="inf"/></transform></shape>', "angle"),
    ("envmap_scale_nan", '<emitter type="envmap"><string name="filename" value="../exr/ok.exr"/><float name="scale" value="nan"/></emitter>', "scale"),
    ("point_position_nan", '<emitter type="point"><point name="position" x="nan" y="0" z="0"/></emitter>', "position"),
    ("unknown_ref", '<shape type="sphere"><ref id="nothing"/></shape>', "nothing"),
    ("duplicate_id", '<bsdf type="diffuse" id="a"/><bsdf type="diffuse" id="a"/>', "duplicate id"),
    ("obj_missing", '<shape type="obj"><string name="filename" value="nope.obj"/></shape>', "nope.obj"),
    ("ply_hostile", '<shape type="ply"><string name="filename" value="../ply/vertex_count_huge.ply"/></shape>', "vertex_count_huge.ply"),
    ("bitmap_corrupt", '<shape type="sphere"><bsdf type="diffuse"><texture type="bitmap" name="reflectance"><string name="filename" value="../exr/huge_window.exr"/></texture></bsdf></shape>', "huge_window.exr"),
    ("bitmap_png_huge", '<shape type="sphere"><bsdf type="diffuse"><texture type="bitmap" name="reflectance"><string name="filename" value="../png/huge_dims.png"/></texture></bsdf></shape>', "huge_dims.png"),
    ("envmap_text", '<emitter type="envmap"><string name="filename" value="../exr/text.exr"/></emitter>', "text.exr"),
    ("envmap_nan_texels", '<emitter type="envmap"><string name="filename" value="../exr/nan_pixels.exr"/></emitter>', "nan_pixels.exr"),
    ("spd_garbage", '<emitter type="constant"><spectrum name="radiance" filename="../misc/garbage.spd"/></emitter>', "garbage.spd"),
    ("checker_nan", '<shape type="sphere"><bsdf type="diffuse"><texture type="checkerboard" name="reflectance"><float name="color0" value="nan"/></texture></bsdf></shape>', "color0"),
    ("to_uv_nan", '<shape type="sphere"><bsdf type="diffuse"><texture type="checkerboard" name="reflectance"><transform name="to_uv"><scale x="nan"/></transform></texture></bsdf></shape>', "scale"),
]:
    xml_case(cid, xml_scene(body), f"fail:{cid}.xml|{culprit}")

for cid, sensor, culprit in [
    ("fov_nan", SENSOR.replace('value="40"', 'value="nan"'), "fov"),
    ("fov_zero", SENSOR.replace('value="40"', 'value="0"'), "fov"),
    ("film_huge", SENSOR.replace('name="width" value="8"', 'name="width" value="65536"').replace(
        'name="height" value="8"', 'name="height" value="65536"'), "65536×65536"),
    ("film_negative", SENSOR.replace('name="width" value="8"', 'name="width" value="-8"'), "width"),
    ("film_int_overflow", SENSOR.replace('name="width" value="8"', 'name="width" value="99999999999999999999999"'), "width"),
    ("spp_zero", SENSOR.replace('name="sample_count" value="1"', 'name="sample_count" value="0"'), "sample_count"),
    ("spp_huge", SENSOR.replace('name="sample_count" value="1"', 'name="sample_count" value="1e12"'), "sample_count"),
    ("lookat_nan", SENSOR.replace('origin="0,0,5"', 'origin="nan,0,5"'), "lookat"),
    ("near_clip_nan", SENSOR.replace("</sensor>", '<float name="near_clip" value="nan"/></sensor>'), "near_clip"),
    ("gaussian_nan", SENSOR.replace('<integer name="height" value="8"/>',
     '<integer name="height" value="8"/><rfilter type="gaussian"><float name="stddev" value="nan"/></rfilter>'), "stddev"),
    ("tent_huge", SENSOR.replace('<integer name="height" value="8"/>',
     '<integer name="height" value="8"/><rfilter type="tent"><float name="radius" value="1e30"/></rfilter>'), "radius"),
]:
    xml_case(cid, xml_scene(SPHERE, sensor), f"fail:{cid}.xml|{culprit}")
xml_case("max_depth_bad", xml_scene(SPHERE + '<integrator type="path"><integer name="max_depth" value="-7"/></integrator>'),
         "fail:max_depth_bad.xml|max_depth")
MIRRORS = ('<shape type="rectangle"><transform name="to_world"><translate z="-1"/></transform>'
           '<bsdf type="conductor"/></shape><shape type="rectangle"><transform name="to_world">'
           '<rotate y="1" angle="180"/><translate z="6"/></transform><bsdf type="conductor"/></shape>'
           '<emitter type="constant"/>')
xml_case("mirror_box_no_roulette", xml_scene(MIRRORS + '<integrator type="path"><integer name="rr_depth" value="2000000000"/></integrator>'),
         "fail:mirror_box_no_roulette.xml|rr_depth")
xml_case("mirror_box_deep", xml_scene(MIRRORS + '<integrator type="path"><integer name="max_depth" value="1000"/><integer name="rr_depth" value="1000"/></integrator>'),
         "ok")
xml_case("spp_above_cap", xml_scene(SPHERE, SENSOR.replace('name="sample_count" value="1"', 'name="sample_count" value="2000000"')),
         "fail:spp_above_cap.xml|2000000")
xml_case("param_undefined", xml_scene('<shape type="sphere"><float name="radius" value="$r"/></shape>'),
         "fail:param_undefined.xml|$r")
xml_case("define_nan", xml_scene('<default name="r" value="1"/><shape type="sphere"><float name="radius" value="$r"/></shape>'),
         "fail:define_nan.xml|radius", "-D r=nan")
xml_case("define_res_huge", xml_scene(SPHERE, SENSOR.replace('name="width" value="8"', 'name="width" value="$res"').replace(
    'name="height" value="8"', 'name="height" value="$res"').replace("<sensor", '<default name="res" value="8"/><sensor')),
    "fail:define_res_huge.xml|60000×60000", "-D res=60000")

# --------------------------------------------------------------------------------- render CLI

OKX = "{C}/xml/ok_sphere.xml"
for cid, opt, culprit in [
    ("exposure_nan", "--exposure nan", "--exposure"),
    ("exposure_inf", "--exposure inf", "--exposure"),
    ("exposure_negative", "--exposure -1", "--exposure"),
    ("resolution_huge", "--resolution 200000x200000", "--resolution"),
    ("resolution_zero", "--resolution 0x5", "--resolution"),
    ("spp_zero", "--spp 0", "--spp"),
    ("threads_zero", "--threads 0", "--threads"),
    ("threads_huge", "--threads 100000000", "--threads"),
    ("sample_range_empty", "--sample-range 5:5", "--sample-range"),
    ("max_depth_bad", "--max-depth -9", "--max-depth"),
    ("fresnel_splits_huge", "--fresnel-splits 1000000000", "--fresnel-splits"),
]:
    case(f"render_{cid}", f"fail:{culprit}", f"render {OKX} -o {{O}}/out.exr {opt}")
case("render_output_not_exr", "fail:out.png", f"render {OKX} -o {{O}}/out.png")
case("render_scene_missing", "fail:missing.xml", "render {C}/missing.xml -o {O}/out.exr")
case("render_scene_unknown_ext", "fail:not_a_dir", "render {C}/not_a_dir -o {O}/out.exr")
case("render_output_is_dir", "fail:dir.exr", f"render {OKX} -o {{C}}/dir.exr")
write("dir.exr/keep", "")

# --------------------------------------------------------------------------------- PLY / OBJ


def ply_ascii(nv, nf, verts, faces, extra_header=""):
    head = f"ply\nformat ascii 1.0\nelement vertex {nv}\nproperty float x\nproperty float y\nproperty float z\n"
    head += f"element face {nf}\nproperty list uchar int vertex_indices\n{extra_header}end_header\n"
    return head + "".join(verts) + "".join(faces)


TRI_V = ["0 0 0\n", "1 0 0\n", "0 1 0\n"]
TRI_F = ["3 0 1 2\n"]


def mesh_case(cid, ext, data, expect):
    rel = write(f"{ext}/{cid}.{ext}", data)
    case(f"{ext}_{cid}", expect, f"render {{C}}/{rel} -o {{O}}/out.exr --spp 1 --resolution 8x8")


mesh_case("ok", "ply", ply_ascii(3, 1, TRI_V, TRI_F), "ok")
mesh_case("vertex_count_huge", "ply", ply_ascii(4000000000, 1, TRI_V, TRI_F), "fail:vertex_count_huge.ply|vertex")
mesh_case("vertex_count_overflow", "ply", ply_ascii(2**64 + 3, 1, TRI_V, TRI_F), "fail:vertex_count_overflow.ply")
mesh_case("face_count_huge", "ply", ply_ascii(3, 3000000000, TRI_V, TRI_F), "fail:face_count_huge.ply|face")
mesh_case("index_out_of_range", "ply", ply_ascii(3, 1, TRI_V, ["3 0 1 99\n"]), "fail:index_out_of_range.ply|99")
mesh_case("index_negative", "ply", ply_ascii(3, 1, TRI_V, ["3 0 1 -1\n"]), "fail:index_negative.ply|-1")
mesh_case("coords_nan", "ply", ply_ascii(3, 1, ["nan 0 0\n", "1 0 0\n", "0 1 0\n"], TRI_F), "fail:coords_nan.ply")
mesh_case("coords_inf", "ply", ply_ascii(3, 1, ["1e39 0 0\n", "1 0 0\n", "0 1 0\n"], TRI_F), "fail:coords_inf.ply")
mesh_case("truncated_body", "ply", ply_ascii(3, 1, TRI_V[:2], []), "fail:truncated_body.ply")
mesh_case("no_end_header", "ply", "ply\nformat ascii 1.0\nelement vertex 3\n", "fail:no_end_header.ply")
mesh_case("not_ply", "ply", "hello\n", "fail:not_ply.ply")
mesh_case("empty", "ply", "", "fail:empty.ply")
mesh_case("garbage", "ply", bytes(range(256)) * 4, "fail:garbage.ply")
mesh_case("format_unknown", "ply", ply_ascii(3, 1, TRI_V, TRI_F).replace("ascii 1.0", "weird 1.0"), "fail:format_unknown.ply")
mesh_case("no_faces", "ply", ply_ascii(3, 0, TRI_V, []), "fail:no_faces.ply|face")
mesh_case("face_two_vertices", "ply", ply_ascii(3, 1, TRI_V, ["2 0 1\n"]), "fail:face_two_vertices.ply|face 0")
mesh_case("face_list_text", "ply", ply_ascii(3, 1, TRI_V, ["3 a b c\n"]), "fail:face_list_text.ply")
mesh_case("binary_truncated", "ply",
          b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
          b"property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n" + b"\0" * 20,
          "fail:binary_truncated.ply")
mesh_case("binary_list_uint_count", "ply",
          b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
          b"property float z\nelement face 1\nproperty list uint int vertex_indices\nend_header\n"
          + struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0) + struct.pack("<I", 4000000000) + b"\0" * 12,
          "fail:binary_list_uint_count.ply")
mesh_case("binary_huge_vertex", "ply",
          b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000\nproperty float x\nproperty float y\n"
          b"property float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n" + b"\0" * 64,
          "fail:binary_huge_vertex.ply|vertex")
mesh_case("face_without_properties", "ply",
          "ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\n"
          "property float z\nelement face 9223372036854775807\nend_header\n" + "\0" * 36,
          "fail:face_without_properties.ply|face")
mesh_case("ascii_count_past_end", "ply", ply_ascii(3000000, 1, TRI_V, TRI_F), "fail:ascii_count_past_end.ply|vertex")
mesh_case("big_polygon", "ply", ply_ascii(3, 1, TRI_V, ["255 " + " ".join(str(i % 3) for i in range(255)) + "\n"]), "ok")

mesh_case("ok", "obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "ok")
mesh_case("index_out_of_range", "obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99\n", "fail:index_out_of_range.obj")
mesh_case("index_zero", "obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 0 1 2\n", "fail:index_zero.obj")
mesh_case("index_negative_far", "obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf -1 -2 -9\n", "fail:index_negative_far.obj")
mesh_case("index_huge", "obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 99999999999999999999\n", "fail:index_huge.obj")
mesh_case("coords_nan", "obj", "v nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "fail:coords_nan.obj")
mesh_case("coords_overflow", "obj", "v 1e39 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "fail:coords_overflow.obj")
mesh_case("vertex_text", "obj", "v a b c\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "fail:vertex_text.obj")
mesh_case("empty", "obj", "", "fail:empty.obj")
mesh_case("garbage", "obj", bytes(range(256)) * 4, "fail:garbage.obj")
mesh_case("no_faces", "obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\n", "fail:no_faces.obj")
mesh_case("normal_index_out_of_range", "obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 1\nf 1//7 2//1 3//1\n",
          "fail:normal_index_out_of_range.obj")
mesh_case("uv_index_out_of_range", "obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nf 1/5 2/1 3/1\n",
          "fail:uv_index_out_of_range.obj")
mesh_case("mtllib_missing", "obj", "mtllib nope.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "ok")
mesh_case("huge_polygon", "obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf " + " ".join(str(1 + i % 3) for i in range(30000)) + "\n", "ok")

# -------------------------------------------------------------------------------------- EXR


def exr_attr(name, typ, data):
    return name.encode() + b"\0" + typ.encode() + b"\0" + struct.pack("<i", len(data)) + data


def exr_bytes(w, h, channels=("B", "G", "R"), compression=0, window=None, pixel=0.5,
              body=None, offsets=None, chlist_override=None):
    x0, y0, x1, y1 = window if window else (0, 0, w - 1, h - 1)
    chl = b"".join(c.encode() + b"\0" + struct.pack("<iBBBBii", 2, 0, 0, 0, 0, 1, 1) for c in channels) + b"\0"
    if chlist_override is not None:
        chl = chlist_override
    head = b"\x76\x2f\x31\x01" + struct.pack("<I", 2)
    head += exr_attr("channels", "chlist", chl)
    head += exr_attr("compression", "compression", bytes([compression]))
    head += exr_attr("dataWindow", "box2i", struct.pack("<4i", x0, y0, x1, y1))
    head += exr_attr("displayWindow", "box2i", struct.pack("<4i", x0, y0, x1, y1))
    head += exr_attr("lineOrder", "lineOrder", b"\0")
    head += exr_attr("pixelAspectRatio", "float", struct.pack("<f", 1.0))
    head += exr_attr("screenWindowCenter", "v2f", struct.pack("<2f", 0, 0))
    head += exr_attr("screenWindowWidth", "float", struct.pack("<f", 1.0))
    head += b"\0"
    if body is None:
        rows = []
        for y in range(h):
            line = b"".join(struct.pack("<f", pixel) * w for _ in channels)
            rows.append(struct.pack("<ii", y0 + y, len(line)) + line)
        table_len = 8 * h
        offs, pos = [], len(head) + table_len
        for r in rows:
            offs.append(pos)
            pos += len(r)
        if offsets is not None:
            offs = offsets
        return head + b"".join(struct.pack("<Q", o) for o in offs) + b"".join(rows)
    return head + body


write("exr/ok.exr", exr_bytes(4, 2))
write("exr/huge_window.exr", exr_bytes(4, 2, window=(0, 0, 999999, 999999), body=b"\0" * 4096))
write("exr/huge_window_zip.exr", exr_bytes(4, 2, compression=3, window=(0, 0, 199999, 49999),
                                            body=zlib.compress(b"\0" * 65536) * 4))
write("exr/negative_window.exr", exr_bytes(4, 2, window=(10, 10, 0, 0), body=b"\0" * 64))
write("exr/window_overflow.exr", exr_bytes(4, 2, window=(-2**31, -2**31, 2**31 - 1, 2**31 - 1), body=b"\0" * 64))
write("exr/truncated.exr", exr_bytes(4, 2)[:-20])
write("exr/header_only.exr", exr_bytes(4, 2)[:60])
write("exr/text.exr", "this is not an EXR file\n")
write("exr/empty.exr", "")
write("exr/nan_pixels.exr", exr_bytes(4, 2, pixel=float("nan")))
write("exr/inf_pixels.exr", exr_bytes(4, 2, pixel=float("inf")))
write("exr/bad_offsets.exr", exr_bytes(4, 2, offsets=[2**62, 2**63]))
write("exr/many_channels.exr", exr_bytes(2, 1, channels=tuple(f"c{i:04d}" for i in range(1100))))
write("exr/no_channels.exr", exr_bytes(4, 2, channels=()))
write("exr/bad_chlist.exr", exr_bytes(4, 2, chlist_override=b"R\0" + struct.pack("<i", 77) + b"\0" * 12 + b"\0"))
write("exr/bad_compression.exr", exr_bytes(4, 2, compression=99))
blob = bytearray(exr_bytes(16, 16, compression=3, body=b""))
write("exr/zip_garbage.exr", bytes(blob) + struct.pack("<Q", len(blob) + 8) + struct.pack("<ii", 0, 100) + b"\x78\x9c" + b"\xff" * 98)
# The studio map with a run of bytes flipped in its header, as a fuzzer would.
studio = open(os.path.join(ROOT, "scenes", "textures", "studio.exr"), "rb").read()
flipped = bytearray(studio[:4096])
for i in range(300, 340):
    flipped[i] ^= 0xA5
write("exr/studio_flipped_head.exr", bytes(flipped))

for name, expect in [
    ("huge_window", "fail:huge_window.exr"),
    ("huge_window_zip", "fail:huge_window_zip.exr"),
    ("negative_window", "fail:negative_window.exr"),
    ("window_overflow", "fail:window_overflow.exr"),
    ("truncated", "fail:truncated.exr"),
    ("header_only", "fail:header_only.exr"),
    ("text", "fail:text.exr"),
    ("empty", "fail:empty.exr"),
    ("bad_offsets", "fail:bad_offsets.exr"),
    ("many_channels", "fail:many_channels.exr"),
    ("no_channels", "fail:no_channels.exr"),
    ("bad_chlist", "fail:bad_chlist.exr"),
    ("bad_compression", "fail:bad_compression.exr"),
    ("zip_garbage", "fail:zip_garbage.exr"),
    ("studio_flipped_head", "fail:studio_flipped_head.exr"),
]:
    case(f"exr_compare_{name}", expect, f"compare {{C}}/exr/{name}.exr {{C}}/exr/ok.exr")
    xml_name = f"exr_env_{name}"
    rel = write(f"xml/{xml_name}.xml", xml_scene(
        SPHERE + f'<emitter type="envmap"><string name="filename" value="../exr/{name}.exr"/></emitter>'))
    case(f"exr_envmap_{name}", expect, f"render {{C}}/{rel} -o {{O}}/out.exr")
case("exr_compare_ok", "ok", "compare {C}/exr/ok.exr {C}/exr/ok.exr")
case("exr_compare_nan", "fail:nan_pixels.exr|not finite", "compare {C}/exr/nan_pixels.exr {C}/exr/ok.exr")
case("compare_downsample_zero", "fail:--downsample", "compare {C}/exr/ok.exr {C}/exr/ok.exr --downsample 0")
write("exr/other_size.exr", exr_bytes(3, 2))
case("compare_size_mismatch", "fail:other_size.exr", "compare {C}/exr/ok.exr {C}/exr/other_size.exr")

# -------------------------------------------------------------------------------------- PNG


def png_chunk(t, data):
    return struct.pack(">I", len(data)) + t + data + struct.pack(">I", zlib.crc32(t + data) & 0xFFFFFFFF)


def png_bytes(w, h, raw=None, declared=None):
    dw, dh = declared or (w, h)
    ihdr = struct.pack(">IIBBBBB", dw, dh, 8, 2, 0, 0, 0)
    if raw is None:
        raw = b"".join(b"\0" + b"\x80\x40\x20" * w for _ in range(h))
    return b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", ihdr) + png_chunk(b"IDAT", zlib.compress(raw)) + png_chunk(b"IEND", b"")


write("png/ok.png", png_bytes(4, 4))
write("png/huge_dims.png", png_bytes(4, 4, declared=(100000, 100000)))
write("png/huge_dims_bomb.png", png_bytes(1, 1, raw=b"\0" * (20000 * 3 + 1) * 200, declared=(20000, 20000)))
write("png/truncated.png", png_bytes(4, 4)[:40])
write("png/garbage.png", b"\x89PNG\r\n\x1a\n" + bytes(range(256)))
for name in ["huge_dims", "huge_dims_bomb", "truncated", "garbage"]:
    rel = write(f"xml/png_{name}.xml", xml_scene(
        '<shape type="sphere"><bsdf type="diffuse"><texture type="bitmap" name="reflectance">'
        f'<string name="filename" value="../png/{name}.png"/></texture></bsdf></shape>'))
    case(f"png_bitmap_{name}", f"fail:{name}.png", f"render {{C}}/{rel} -o {{O}}/out.exr")
write("misc/huge.hdr", b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 100000 +X 100000\n" + b"\0" * 64)
rel = write("xml/hdr_huge.xml", xml_scene(
    SPHERE + '<emitter type="envmap"><string name="filename" value="../misc/huge.hdr"/></emitter>'))
case("hdr_envmap_huge", "fail:huge.hdr", f"render {{C}}/{rel} -o {{O}}/out.exr")
write("misc/garbage.spd", "400 0.5\n500 banana\n")

# ------------------------------------------------------------------------------------- glTF

TRI = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0)
IDX = struct.pack("<3H", 0, 1, 2) + b"\0\0"
BUF = TRI + IDX


def data_uri(b):
    return "data:application/octet-stream;base64," + base64.b64encode(b).decode()


def gltf_doc(**over):
    doc = {
        "asset": {"version": "2.0"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
        "accessors": [
            {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
             "min": [0, 0, 0], "max": [1, 1, 0]},
            {"bufferView": 1, "componentType": 5123, "count": 3, "type": "SCALAR"},
        ],
        "bufferViews": [
            {"buffer": 0, "byteOffset": 0, "byteLength": 36},
            {"buffer": 0, "byteOffset": 36, "byteLength": 6},
        ],
        "buffers": [{"byteLength": len(BUF), "uri": data_uri(BUF)}],
    }
    for k, v in over.items():
        if v is None:
            doc.pop(k, None)
        else:
            doc[k] = v
    return doc


def gltf_case(cid, doc, expect, raw=None):
    text = raw if raw is not None else json.dumps(doc)
    rel = write(f"gltf/{cid}.gltf", text)
    case(f"gltf_{cid}", expect, f"render {{C}}/{rel} -o {{O}}/out.exr --spp 1 --resolution 8x8")


def mod(doc, path, value):
    d = doc
    for p in path[:-1]:
        d = d[p]
    if value is None:
        del d[path[-1]]
    else:
        d[path[-1]] = value
    return doc


gltf_case("ok", gltf_doc(), "ok")
gltf_case("self_child", gltf_doc(nodes=[{"mesh": 0, "children": [0]}]), "fail:self_child.gltf|node 0")
gltf_case("cycle_two", gltf_doc(nodes=[{"mesh": 0, "children": [1]}, {"children": [0]}]), "fail:cycle_two.gltf|node")
gltf_case("two_parents", gltf_doc(nodes=[{"children": [2]}, {"children": [2]}, {"mesh": 0}],
                                  scenes=[{"nodes": [0, 1]}]), "fail:two_parents.gltf|node 2")
gltf_case("dag_explosion", gltf_doc(nodes=[{"children": [i + 1] * 10} for i in range(12)] + [{"mesh": 0}]),
          "fail:dag_explosion.gltf|node")
gltf_case("child_out_of_range", gltf_doc(nodes=[{"mesh": 0, "children": [7]}]), "fail:child_out_of_range.gltf|nodes")
gltf_case("scene_node_out_of_range", gltf_doc(scenes=[{"nodes": [5]}]), "fail:scene_node_out_of_range.gltf|nodes")
gltf_case("scene_index_out_of_range", gltf_doc(scene=4), "fail:scene_index_out_of_range.gltf|scene")
gltf_case("mesh_out_of_range", gltf_doc(nodes=[{"mesh": 3}]), "fail:mesh_out_of_range.gltf|mesh")
gltf_case("accessor_out_of_range", mod(gltf_doc(), ["meshes", 0, "primitives", 0, "attributes", "POSITION"], 99),
          "fail:accessor_out_of_range.gltf|accessor")
gltf_case("position_index_u64_max", mod(gltf_doc(), ["meshes", 0, "primitives", 0, "attributes", "POSITION"],
          2**64 - 1), "fail:position_index_u64_max.gltf|POSITION")
gltf_case("indices_out_of_range", mod(gltf_doc(), ["meshes", 0, "primitives", 0, "indices"], 99),
          "fail:indices_out_of_range.gltf|indices")
gltf_case("float_indices", mod(gltf_doc(), ["accessors", 1, "componentType"], 5126),
          "fail:float_indices.gltf|indices")
gltf_case("indices_vec3", mod(gltf_doc(), ["accessors", 1, "type"], "VEC3"), "fail:indices_vec3.gltf|indices")
gltf_case("position_vec2", mod(gltf_doc(), ["accessors", 0, "type"], "VEC2"), "fail:position_vec2.gltf|POSITION")
gltf_case("position_ubyte", mod(gltf_doc(), ["accessors", 0, "componentType"], 5121), "fail:position_ubyte.gltf|POSITION")
gltf_case("index_value_out_of_range", gltf_doc(buffers=[{"byteLength": len(BUF), "uri": data_uri(
    TRI + struct.pack("<3H", 0, 1, 60000) + b"\0\0")}]), "fail:index_value_out_of_range.gltf|60000")
gltf_case("view_past_buffer", mod(gltf_doc(), ["bufferViews", 1, "byteOffset"], 4000),
          "fail:view_past_buffer.gltf|bufferViews[1]")
gltf_case("view_offset_overflow", mod(gltf_doc(), ["bufferViews", 1, "byteOffset"], 2**64 - 2),
          "fail:view_offset_overflow.gltf")
gltf_case("view_length_huge", mod(gltf_doc(), ["bufferViews", 0, "byteLength"], 2**53),
          "fail:view_length_huge.gltf|bufferViews[0]")
gltf_case("view_buffer_out_of_range", mod(gltf_doc(), ["bufferViews", 0, "buffer"], 9),
          "fail:view_buffer_out_of_range.gltf|buffer")
gltf_case("accessor_longer_than_view", mod(gltf_doc(), ["accessors", 0, "count"], 30),
          "fail:accessor_longer_than_view.gltf|accessors[0]")
gltf_case("accessor_count_huge", mod(gltf_doc(), ["accessors", 0, "count"], 4000000000),
          "fail:accessor_count_huge.gltf|accessors[0]")
gltf_case("accessor_offset_past_view", mod(gltf_doc(), ["accessors", 0, "byteOffset"], 1000),
          "fail:accessor_offset_past_view.gltf|accessors[0]")
gltf_case("accessor_no_view", mod(gltf_doc(), ["accessors", 0, "bufferView"], None),
          "fail:accessor_no_view.gltf|accessors[0]")
gltf_case("stride_odd", mod(gltf_doc(), ["bufferViews", 0, "byteStride"], 3), "fail:stride_odd.gltf|byteStride")
gltf_case("stride_huge", mod(gltf_doc(), ["bufferViews", 0, "byteStride"], 100000), "fail:stride_huge.gltf|byteStride")
gltf_case("stride_small", mod(gltf_doc(), ["bufferViews", 0, "byteStride"], 4), "fail:stride_small.gltf")
gltf_case("buffer_length_huge", mod(gltf_doc(), ["buffers", 0, "byteLength"], 2**50),
          "fail:buffer_length_huge.gltf|buffer")
gltf_case("buffer_missing_file", mod(gltf_doc(), ["buffers", 0, "uri"], "missing.bin"),
          "fail:buffer_missing_file.gltf|missing.bin")
gltf_case("buffer_bad_base64", mod(gltf_doc(), ["buffers", 0, "uri"], "data:application/octet-stream;base64,!!!!"),
          "fail:buffer_bad_base64.gltf|buffer")
gltf_case("buffer_short", mod(gltf_doc(), ["buffers", 0, "uri"], data_uri(BUF[:10])),
          "fail:buffer_short.gltf|buffer")
gltf_case("buffer_scheme", mod(gltf_doc(), ["buffers", 0, "uri"], "http://example.com/a.bin"),
          "fail:buffer_scheme.gltf|http://example.com/a.bin")
gltf_case("buffer_no_uri", mod(gltf_doc(), ["buffers", 0, "uri"], None), "fail:buffer_no_uri.gltf|buffer")
gltf_case("sparse_hostile", mod(gltf_doc(), ["accessors", 0, "sparse"], {
    "count": 4000000000, "indices": {"bufferView": 1, "componentType": 5123},
    "values": {"bufferView": 0}}), "fail:sparse_hostile.gltf|accessors[0]")
gltf_case("sparse_index_oob", mod(gltf_doc(), ["accessors", 0, "sparse"], {
    "count": 1, "indices": {"bufferView": 1, "componentType": 5123, "byteOffset": 4},
    "values": {"bufferView": 0}}), "fail:sparse_index_oob.gltf|sparse")
img_doc = gltf_doc(images=[{"name": "nothing"}], textures=[{"source": 0}],
                   materials=[{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}])
img_doc["meshes"][0]["primitives"][0]["material"] = 0
gltf_case("image_no_source", img_doc, "fail:image_no_source.gltf|image")
img_doc2 = json.loads(json.dumps(img_doc))
img_doc2["images"] = [{"bufferView": 1, "mimeType": "image/png"}]
img_doc2["bufferViews"][1]["byteOffset"] = 44
gltf_case("image_view_past_buffer", img_doc2, "fail:image_view_past_buffer.gltf|bufferViews[1]")
img_doc3 = json.loads(json.dumps(img_doc))
img_doc3["images"] = [{"uri": "../png/huge_dims.png"}]
gltf_case("image_huge_png", img_doc3, "fail:image_huge_png.gltf|huge_dims.png")
img_doc4 = json.loads(json.dumps(img_doc))
img_doc4["images"] = [{"uri": "missing.png"}]
gltf_case("image_missing", img_doc4, "fail:image_missing.gltf|missing.png")
img_doc5 = json.loads(json.dumps(img_doc))
img_doc5["textures"] = [{"source": 5}]
gltf_case("texture_source_out_of_range", img_doc5, "fail:texture_source_out_of_range.gltf|source")
img_doc6 = json.loads(json.dumps(img_doc))
img_doc6["images"] = [{"uri": "../png/ok.png"}]
img_doc6["materials"][0]["pbrMetallicRoughness"]["baseColorTexture"]["index"] = 4
gltf_case("material_texture_out_of_range", img_doc6, "fail:material_texture_out_of_range.gltf|texture")
irid = gltf_doc(materials=[{"extensions": {"KHR_materials_iridescence": {
    "iridescenceFactor": 1, "iridescenceIor": float("1e300"), "iridescenceThicknessMaximum": 400}}}])
irid["meshes"][0]["primitives"][0]["material"] = 0
gltf_case("iridescence_ior_huge", irid, "fail:iridescence_ior_huge.gltf|iridescenceIor")
irid2 = json.loads(json.dumps(irid))
irid2["materials"][0]["extensions"]["KHR_materials_iridescence"] = {
    "iridescenceFactor": 1, "iridescenceThicknessMaximum": 1e300}
gltf_case("iridescence_thickness_huge", irid2, "fail:iridescence_thickness_huge.gltf|iridescenceThickness")
irid3 = json.loads(json.dumps(irid))
irid3["materials"][0]["extensions"]["KHR_materials_iridescence"] = {
    "iridescenceFactor": 1, "iridescenceThicknessTexture": {"index": 9}}
gltf_case("iridescence_texture_out_of_range", irid3, "fail:iridescence_texture_out_of_range.gltf|texture")
gltf_case("material_out_of_range", mod(gltf_doc(), ["meshes", 0, "primitives", 0, "material"], 3),
          "fail:material_out_of_range.gltf|material")
gltf_case("node_scale_overflow", gltf_doc(nodes=[{"mesh": 0, "scale": [1e39, 1, 1]}]),
          "fail:node_scale_overflow.gltf|node 0")
gltf_case("node_matrix_singular", gltf_doc(nodes=[{"mesh": 0, "matrix": [0] * 16}]), "fail:node_matrix_singular.gltf|node 0")
gltf_case("camera_yfov_zero", gltf_doc(nodes=[{"mesh": 0}, {"camera": 0}], scenes=[{"nodes": [0, 1]}],
                                       cameras=[{"type": "perspective", "perspective": {"yfov": 0, "znear": 0.1}}]),
          "fail:camera_yfov_zero.gltf|yfov")
gltf_case("camera_aspect_huge", gltf_doc(nodes=[{"mesh": 0}, {"camera": 0}], scenes=[{"nodes": [0, 1]}],
                                         cameras=[{"type": "perspective", "perspective": {
                                             "yfov": 0.8, "znear": 0.1, "aspectRatio": 1e30}}]),
          "fail:camera_aspect_huge.gltf|aspectRatio")
gltf_case("camera_out_of_range", gltf_doc(nodes=[{"mesh": 0, "camera": 4}]), "fail:camera_out_of_range.gltf|camera")
gltf_case("no_scenes", gltf_doc(scenes=None, scene=None), "fail:no_scenes.gltf|scene")
gltf_case("no_meshes", gltf_doc(nodes=[{}]), "fail:no_meshes.gltf|mesh")
gltf_case("mesh_no_primitives", gltf_doc(meshes=[{"primitives": []}]), "fail:mesh_no_primitives.gltf")
gltf_case("not_json", None, "fail:not_json.gltf", raw="{ not json")
gltf_case("empty", None, "fail:empty.gltf", raw="")
gltf_case("deep_json", None, "fail:deep_json.gltf", raw='{"asset": {"version": "2.0"}, "extras": '
          + "[" * 20000 + "]" * 20000 + "}")
gltf_case("version_1", gltf_doc(asset={"version": "1.0"}), "fail:version_1.gltf|version")
gltf_case("wrong_types", None, "fail:wrong_types.gltf", raw=json.dumps(gltf_doc()).replace('"count": 3', '"count": "three"'))
gltf_case("negative_count", None, "fail:negative_count.gltf", raw=json.dumps(gltf_doc()).replace('"count": 3', '"count": -3'))
gltf_case("mode_points", mod(gltf_doc(), ["meshes", 0, "primitives", 0, "mode"], 0), "fail:mode_points.gltf|triangle")
gltf_case("mode_invalid", mod(gltf_doc(), ["meshes", 0, "primitives", 0, "mode"], 99), "fail:mode_invalid.gltf|mode")
gltf_case("index_count_not_triple", gltf_doc(accessors=[
    {"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3", "min": [0, 0, 0], "max": [1, 1, 0]},
    {"bufferView": 1, "componentType": 5123, "count": 2, "type": "SCALAR"}]), "fail:index_count_not_triple.gltf|3")
gltf_case("positions_nan", gltf_doc(buffers=[{"byteLength": len(BUF), "uri": data_uri(
    struct.pack("<9f", float("nan"), 0, 0, 1, 0, 0, 0, 1, 0) + IDX)}]), "fail:positions_nan.gltf")
gltf_case("normals_wrong_count", json.loads(json.dumps(gltf_doc()).replace(
    '"attributes": {"POSITION": 0}', '"attributes": {"POSITION": 0, "NORMAL": 1}')), "fail:normals_wrong_count.gltf|NORMAL")


def glb(json_text, bin_data, total_len=None, json_len=None, bin_len=None):
    j = json_text.encode()
    while len(j) % 4:
        j += b" "
    b_ = bin_data
    while len(b_) % 4:
        b_ += b"\0"
    body = struct.pack("<I", json_len if json_len is not None else len(j)) + b"JSON" + j
    body += struct.pack("<I", bin_len if bin_len is not None else len(b_)) + b"BIN\0" + b_
    total = total_len if total_len is not None else 12 + len(body)
    return b"glTF" + struct.pack("<II", 2, total) + body


glb_doc = gltf_doc()
glb_doc["buffers"] = [{"byteLength": len(BUF)}]
for cid, data, expect in [
    ("ok", glb(json.dumps(glb_doc), BUF), "ok"),
    ("length_huge", glb(json.dumps(glb_doc), BUF, total_len=2**32 - 1), "fail:length_huge.glb"),
    ("json_len_huge", glb(json.dumps(glb_doc), BUF, json_len=2**32 - 16), "fail:json_len_huge.glb"),
    ("bin_len_huge", glb(json.dumps(glb_doc), BUF, bin_len=2**32 - 4), "fail:bin_len_huge.glb"),
    ("truncated", glb(json.dumps(glb_doc), BUF)[:50], "fail:truncated.glb"),
    ("no_bin", glb(json.dumps(glb_doc), b"")[:-8], "fail:no_bin.glb"),
    ("magic_only", b"glTF", "fail:magic_only.glb"),
    ("no_accessors", glb(json.dumps({k: v for k, v in glb_doc.items() if k != "accessors"}), BUF),
     "fail:no_accessors.glb|POSITION"),
    ("garbage", bytes(range(256)) * 4, "fail:garbage.glb"),
]:
    rel = write(f"gltf/{cid}.glb", data)
    case(f"glb_{cid}", expect, f"render {{C}}/{rel} -o {{O}}/out.exr --spp 1 --resolution 8x8")

# ------------------------------------------------------------------------ serialized meshes


def serialized_mesh(version=4, vertices=3, faces=1, flags=0x1000, body=None, name=b"tri\0", idx=(0, 1, 2),
                    coords=(0, 0, 0, 1, 0, 0, 0, 1, 0)):
    """One Mitsuba .serialized mesh (header + zlib stream): positions only, single precision."""
    if body is None:
        body = struct.pack("<I", flags) + (name if version == 4 else b"")
        body += struct.pack("<QQ", vertices, faces)
        body += struct.pack(f"<{len(coords)}f", *coords) + struct.pack(f"<{len(idx)}I", *idx)
    return struct.pack("<HH", 0x041C, version) + zlib.compress(body)


def serialized_file(meshes, version=4, table=None, count=None):
    out, offs = b"", []
    for m in meshes:
        offs.append(len(out))
        out += m
    for o in (table if table is not None else offs):
        out += struct.pack("<I" if version == 3 else "<Q", o)
    return out + struct.pack("<I", len(meshes) if count is None else count)


def serialized_case(cid, data, expect, index=0, filename=None):
    if data is not None:
        write(f"serialized/{cid}.serialized", data)
    fname = filename or f"../serialized/{cid}.serialized"
    rel = write(f"xml/serialized_{cid}.xml", xml_scene(
        f'<shape type="serialized"><string name="filename" value="{fname}"/>'
        f'<integer name="shape_index" value="{index}"/></shape>'))
    case(f"serialized_{cid}", expect, f"render {{C}}/{rel} -o {{O}}/out.exr")


serialized_case("ok", serialized_file([serialized_mesh()]), "ok")
serialized_case("second_mesh", serialized_file([serialized_mesh(), serialized_mesh()]), "ok", index=1)
serialized_case("bad_magic", b"\x1d\x04" + serialized_file([serialized_mesh()])[2:], "fail:bad_magic.serialized|magic")
serialized_case("version_9", serialized_file([serialized_mesh()])[:2] + b"\x09\0" + serialized_file([serialized_mesh()])[4:],
                "fail:version_9.serialized|version 9")
serialized_case("truncated", serialized_file([serialized_mesh()])[:20], "fail:truncated.serialized")
serialized_case("empty", b"", "fail:empty.serialized")
serialized_case("garbage", bytes(range(256)) * 8, "fail:garbage.serialized")
# Counts far beyond what the few compressed bytes can expand to (zlib: at most 1032:1).
serialized_case("count_bomb", serialized_file([serialized_mesh(vertices=100_000_000, faces=100_000_000)]),
                "fail:count_bomb.serialized|100000000 vertices|1032")
serialized_case("count_past_limit", serialized_file([serialized_mesh(vertices=2**40)]),
                "fail:count_past_limit.serialized|vertex count")
serialized_case("count_u64_max", serialized_file([serialized_mesh(faces=2**64 - 1)]),
                "fail:count_u64_max.serialized|face count")
# A real decompression bomb: 40 MB of zeros in ~40 KB, declared as 3.3 M vertices — more
# than the stream holds once its faces are counted.
bomb = struct.pack("<I", 0x1000) + b"\0" + struct.pack("<QQ", 3_300_000, 3_300_000) + b"\0" * 40_000_000
serialized_case("zlib_bomb", struct.pack("<HH", 0x041C, 4) + zlib.compress(bomb, 9) + struct.pack("<QI", 0, 1),
                "fail:zlib_bomb.serialized")
serialized_case("index_out_of_range", serialized_file([serialized_mesh(idx=(0, 1, 7))]),
                "fail:index_out_of_range.serialized|vertex 7")
serialized_case("coords_nan", serialized_file([serialized_mesh(coords=(float("nan"),) + (0,) * 8)]),
                "fail:coords_nan.serialized")
serialized_case("name_unterminated", serialized_file([serialized_mesh(name=b"x" * 70000)]),
                "fail:name_unterminated.serialized|name")
serialized_case("shape_index_past_end", serialized_file([serialized_mesh()]), "fail:shape_index_past_end.serialized|shape_index 5",
                index=5)
serialized_case("shape_index_negative", serialized_file([serialized_mesh()]), "fail:shape_index", index=-1)
serialized_case("offset_past_end", serialized_file([serialized_mesh(), serialized_mesh()], table=[0, 2**62]),
                "fail:offset_past_end.serialized|offset", index=1)
serialized_case("count_table_huge", serialized_file([serialized_mesh()], count=2**32 - 1),
                "fail:count_table_huge.serialized", index=7)
serialized_case("v5_tangents", serialized_mesh(version=5, body=struct.pack("<II", 0x1002, 0)) + struct.pack("<QI", 0, 1),
                "fail:v5_tangents.serialized|tangents")
serialized_case("directory", None, "fail:not a regular file", filename="../serialized")
serialized_case("missing", None, "fail:missing.serialized", filename="missing.serialized")

# ----------------------------------------------------------------------------------- include


def include_case(cid, files, expect):
    for name, text in files.items():
        write(f"include/{cid}/{name}", text)
    case(f"include_{cid}", expect, f"render {{C}}/include/{cid}/main.xml -o {{O}}/out.exr")


INC = '<include filename="{}"/>'
include_case("ok", {"main.xml": xml_scene(INC.format("part.xml")), "part.xml": f"<scene version='3.0.0'>{SPHERE}</scene>"},
             "ok")
include_case("self", {"main.xml": xml_scene(SPHERE + INC.format("main.xml"))}, "fail:main.xml|cycle")
include_case("mutual", {"main.xml": xml_scene(SPHERE + INC.format("a.xml")),
                        "a.xml": "<scene version='3.0.0'>" + INC.format("b.xml") + "</scene>",
                        "b.xml": "<scene version='3.0.0'>" + INC.format("a.xml") + "</scene>"}, "fail:cycle|a.xml")
chain = {"main.xml": xml_scene(SPHERE + INC.format("d0.xml"))}
for i in range(20):
    chain[f"d{i}.xml"] = "<scene version='3.0.0'>" + INC.format(f"d{i + 1}.xml") + "</scene>"
chain["d20.xml"] = "<scene version='3.0.0'/>"
include_case("too_deep", chain, "fail:nested deeper than 15")
# Ten includes of a file that includes ten … nine levels: 10⁹ expansions without a cap.
fan = {"main.xml": xml_scene(SPHERE + INC.format("f0.xml") * 10)}
for i in range(9):
    fan[f"f{i}.xml"] = "<scene version='3.0.0'>" + INC.format(f"f{i + 1}.xml") * 10 + "</scene>"
fan["f9.xml"] = "<scene version='3.0.0'><shape type='sphere'/></scene>"
include_case("exponential", fan, "fail:<include> expansions")
include_case("missing", {"main.xml": xml_scene(SPHERE + INC.format("nope.xml"))}, "fail:main.xml|nope.xml")
include_case("directory", {"main.xml": xml_scene(SPHERE + INC.format("sub")), "sub/x.txt": "x"},
             "fail:main.xml|not a regular file")
include_case("dev_zero", {"main.xml": xml_scene(SPHERE + INC.format("/dev/zero"))}, "fail:/dev/zero|not a regular file")
include_case("malformed", {"main.xml": xml_scene(SPHERE + INC.format("bad.xml")), "bad.xml": "<scene version='3.0.0'><shape"},
             "fail:bad.xml|malformed")
include_case("binary", {"main.xml": xml_scene(SPHERE + INC.format("bin.xml")), "bin.xml": bytes(range(256))},
             "fail:bin.xml|UTF-8")
include_case("nan_inside", {"main.xml": xml_scene(INC.format("part.xml")),
                            "part.xml": "<scene version='3.0.0'><shape type='sphere'><float name='radius' value='nan'/></shape></scene>"},
             "fail:part.xml|radius")

# ------------------------------------------------------------------- JPEG / BMP / TGA / PPM


def jpeg_sof(w, h):
    """A JPEG header whose frame declares w×h pixels, with no scan data."""
    sof = struct.pack(">BHHB", 8, h, w, 3) + b"\x01\x22\x00\x02\x11\x00\x03\x11\x00"
    return b"\xff\xd8" + b"\xff\xc0" + struct.pack(">H", len(sof) + 2) + sof + b"\xff\xd9"


def bmp(w, h, bpp=24, data=b""):
    info = struct.pack("<IiiHHIIiiII", 40, w, h, 1, bpp, 0, 0, 2835, 2835, 0, 0)
    return b"BM" + struct.pack("<IHHI", 54 + len(data), 0, 0, 54) + info + data


def tga(w, h, data=b""):
    return struct.pack("<BBBHHBHHHHBB", 0, 0, 2, 0, 0, 0, 0, 0, w, h, 24, 0) + data


IMAGES = {
    "ok.bmp": bmp(2, 2, data=b"\x80" * 16),
    "ok.tga": tga(2, 2, b"\x80" * 12),
    "ok.ppm": b"P6\n2 2\n255\n" + b"\x80" * 12,
    "huge.jpg": jpeg_sof(65500, 65500),
    "truncated.jpg": jpeg_sof(16, 16)[:-2],
    "garbage.jpg": b"\xff\xd8" + bytes(range(256)) * 4,
    "huge.bmp": bmp(100000, 100000),
    "negative_height.bmp": bmp(4, -2**31 + 1),
    "truncated.bmp": bmp(64, 64, data=b"\0" * 10),
    "huge.tga": tga(65535, 65535),
    "truncated.tga": tga(64, 64, b"\0" * 10),
    "huge.ppm": b"P6\n60000 60000\n255\n" + b"\0" * 16,
    "overflow.ppm": b"P6\n18446744073709551617 3\n255\n" + b"\0" * 16,
    "zero.ppm": b"P6\n0 0\n255\n",
    "maxval_huge.ppm": b"P6\n2 2\n99999999\n" + b"\0" * 24,
    "truncated.ppm": b"P6\n64 64\n255\n" + b"\0" * 10,
    "huge.pgm": b"P5\n65536 65536\n255\n",
}
for name, data in IMAGES.items():
    write(f"img/{name}", data)
    stem = name.replace(".", "_")
    rel = write(f"xml/img_{stem}.xml", xml_scene(
        '<shape type="sphere"><bsdf type="diffuse"><texture type="bitmap" name="reflectance">'
        f'<string name="filename" value="../img/{name}"/></texture></bsdf></shape>'))
    case(f"img_bitmap_{stem}", "ok" if name.startswith("ok.") else f"fail:{name}", f"render {{C}}/{rel} -o {{O}}/out.exr")

# ------------------------------------------------------------- EXR provenance (thinfilm merge)


def exr_with_attrs(attrs, w=4, h=2, channels=("B", "G", "R")):
    """An EXR whose header carries text attributes (`string`) beside the required ones."""
    plain = exr_bytes(w, h, channels=channels)
    extra = b"".join(exr_attr(k, "string", v.encode()) for k, v in attrs.items())
    # The header ends at the first NUL that follows the last attribute: insert before it.
    end = plain.index(b"screenWindowWidth\0float\0") + len(b"screenWindowWidth\0float\0") + 8
    head, rest = plain[:end], plain[end + 1:]
    # Offsets in the line table move by the inserted bytes.
    table = struct.unpack(f"<{h}Q", rest[:8 * h])
    table = struct.pack(f"<{h}Q", *(o + len(extra) for o in table))
    return head + extra + b"\0" + table + rest[8 * h:]


def render_attrs(rng="0:16", **over):
    a, b = (int(v) for v in rng.split(":"))
    attrs = {"thinfilm.kind": "render", "thinfilm.sampleRange": rng, "thinfilm.spp": str(b - a),
             "thinfilm.requestedRange": rng, "thinfilm.seed": "1", "thinfilm.sampler": "independent",
             "thinfilm.filter": "box", "thinfilm.imageHash": "00000000deadbeef", "thinfilm.version": "0"}
    attrs.update(over)
    return {k: v for k, v in attrs.items() if v is not None}


def tile_attrs(rows="0:2", **over):
    attrs = {"thinfilm.kind": "fit", "thinfilm.rows": rows, "thinfilm.imageHeight": "4",
             "thinfilm.fitHash": "00000000deadbeef", "thinfilm.filmIor": "1.33", "thinfilm.version": "0"}
    attrs.update(over)
    return {k: v for k, v in attrs.items() if v is not None}


MERGE = {
    "a": render_attrs("0:16"),
    "b": render_attrs("16:32"),
    "c_overlap": render_attrs("8:24"),
    "d_gap": render_attrs("40:48"),
    "e_other_hash": render_attrs("16:32", **{"thinfilm.imageHash": "1111111111111111"}),
    "kind_banana": render_attrs(**{"thinfilm.kind": "banana"}),
    "range_reversed": render_attrs(**{"thinfilm.sampleRange": "16:0"}),
    "range_huge": render_attrs(**{"thinfilm.sampleRange": "0:99999999999"}),
    "range_text": render_attrs(**{"thinfilm.sampleRange": "lots"}),
    "spp_disagrees": render_attrs(**{"thinfilm.spp": "17"}),
    "hash_not_hex": render_attrs(**{"thinfilm.imageHash": "zz"}),
    "seed_missing": render_attrs(**{"thinfilm.seed": None}),
    "seed_negative": render_attrs(**{"thinfilm.seed": "-1"}),
    "tent_no_weights": render_attrs(**{"thinfilm.filter": "tent"}),
}
for name, attrs in MERGE.items():
    write(f"merge/{name}.exr", exr_with_attrs(attrs))
write("merge/b_wide.exr", exr_with_attrs(render_attrs("16:32"), w=5))
write("merge/b_no_r.exr", exr_with_attrs(render_attrs("16:32"), channels=("B", "G")))
write("merge/t0.exr", exr_with_attrs(tile_attrs("0:2"), channels=("Y",)))
write("merge/t1.exr", exr_with_attrs(tile_attrs("2:4"), channels=("Y",)))
write("merge/t1_ior_nan.exr", exr_with_attrs(tile_attrs("2:4", **{"thinfilm.filmIor": "nan"}), channels=("Y",)))
write("merge/t1_rows_outside.exr", exr_with_attrs(tile_attrs("2:4", **{"thinfilm.imageHeight": "3"}), channels=("Y",)))
write("merge/t1_height_huge.exr", exr_with_attrs(tile_attrs("2:4", **{"thinfilm.imageHeight": "4000000000"}), channels=("Y",)))
write("merge/t1_other_fit.exr", exr_with_attrs(tile_attrs("2:4", **{"thinfilm.fitHash": "1"}), channels=("Y",)))
write("merge/plain.exr", exr_bytes(4, 2))
M = "{C}/merge/"
for cid, pieces, expect, extra in [
    ("ok", "a b", "ok", ""),
    ("tiles_ok", "t0 t1", "ok", ""),
    ("overlap", "a c_overlap", "fail:overlap|c_overlap.exr", ""),
    ("gap", "a b d_gap", "fail:missing|d_gap.exr", ""),
    ("other_hash", "a e_other_hash", "fail:different images|e_other_hash.exr", ""),
    ("other_size", "a b_wide", "fail:b_wide.exr", ""),
    ("no_r", "a b_no_r", "fail:b_no_r.exr|'R'", ""),
    ("plain_exr", "plain a", "fail:plain.exr|thinfilm.kind", ""),
    ("kind_banana", "kind_banana", "fail:kind_banana.exr|banana", ""),
    ("range_reversed", "range_reversed", "fail:range_reversed.exr|thinfilm.sampleRange", ""),
    ("range_huge", "range_huge", "fail:range_huge.exr|thinfilm.sampleRange", ""),
    ("range_text", "range_text", "fail:range_text.exr|thinfilm.sampleRange", ""),
    ("spp_disagrees", "spp_disagrees", "fail:spp_disagrees.exr|thinfilm.spp", ""),
    ("hash_not_hex", "hash_not_hex", "fail:hash_not_hex.exr|thinfilm.imageHash", ""),
    ("seed_missing", "seed_missing", "fail:seed_missing.exr|thinfilm.seed", ""),
    ("seed_negative", "seed_negative", "fail:seed_negative.exr|thinfilm.seed", ""),
    ("tent_no_weights", "tent_no_weights", "fail:tent_no_weights.exr|filter_weight", ""),
    ("tile_ior_nan", "t0 t1_ior_nan", "fail:t1_ior_nan.exr|thinfilm.filmIor", ""),
    ("tile_rows_outside", "t0 t1_rows_outside", "fail:t1_rows_outside.exr|rows", ""),
    ("tile_height_huge", "t0 t1_height_huge", "fail:t1_height_huge.exr", ""),
    ("tile_other_fit", "t0 t1_other_fit", "fail:t1_other_fit.exr|different fits", ""),
    ("tile_and_render", "t0 a", "fail:a.exr", ""),
    ("huge_window", "../exr/huge_window", "fail:huge_window.exr", ""),
    ("missing", "a nope", "fail:nope.exr", ""),
    ("exposure_nan", "a b", "fail:--exposure", "--exposure nan"),
]:
    args = " ".join(M + p + ".exr" for p in pieces.split())
    case(f"merge_{cid}", expect, f"merge {args} -o {{O}}/merged.exr {extra}".strip())
case("merge_output_is_input", "fail:also an input", f"merge {M}a.exr {M}b.exr -o {M}a.exr")
case("merge_output_png", "fail:merged.png", f"merge {M}a.exr {M}b.exr -o {{O}}/merged.png")

# ------------------------------------------------------------- more classes (second sweep)
# Zero-length, truncated and huge-declared (sparse) files of every format, lying counts,
# odd-but-legal variants, and the inputs of `figure`, `estimate --spectra` and `merge`.

GIB3 = 3 * 2**30


def sparse_file(rel, data, size=GIB3):
    """A file that starts with `data` and declares `size` bytes (a hole, not disk space)."""
    write(rel, data)
    sparse.append((rel, size))
    return rel


# ENVI: zero-length binary, zero-length header, huge sparse header and cube, CRLF, BOM.
envi_case("binary_empty", envi_header(), "fail:c.img", binary=b"")
envi_case("header_zero_length", "", "fail:c.hdr")
envi_case("header_crlf", envi_header().replace("\n", "\r\n"), "ok")
envi_case("header_bom", "\ufeff" + envi_header(), "ok")
envi_case("header_truncated_mid_key", envi_header()[:40], "fail:c.hdr")
envi_case("header_truncated_in_list", envi_header()[:-30], "fail:c.hdr")
envi_case("bil_truncated", envi_header(interleave="bil"), "fail:c.img|truncated", binary=cube_bytes()[:-4])
envi_case("bip_ok", envi_header(interleave="bip"), "ok")
envi_case("data_type_u16_short", envi_header(data_type=12), "ok", binary=cube_bytes()[: W * H * B * 2])
envi_case("data_type_f64_short", envi_header(data_type=5), "fail:c.img|truncated")
envi_case("bands_string_list", envi_header(wavelength="{a, b, c, d, e, f, g, h}"), "fail:c.hdr|wavelength")
envi_case("wavelength_1e400", envi_header(wavelength="{" + ", ".join(["1e400"] * B) + "}"), "fail:c.hdr|wavelength")
envi_case("key_repeated_10k", envi_header() + "description = x\n" * 10000, "ok")
d = "envi/header_sparse"
sparse_file(f"{d}/c.hdr", envi_header())
write(f"{d}/c.img", cube_bytes())
write(f"{d}/capture.json", capture_json([(20, "c.hdr")]))
case("envi_header_sparse", "fail:c.hdr", f"estimate {{C}}/{d} --out {{O}}/fit --film-ior 1.4 --quiet")
d = "envi/cube_sparse"
write(f"{d}/c.hdr", envi_header(samples=2**15, lines=2**15, bands=B))
sparse_file(f"{d}/c.img", b"", 2**15 * 2**15 * B * 4)
write(f"{d}/capture.json", capture_json([(20, "c.hdr")]))
case("envi_cube_sparse_huge", "fail:c.hdr", f"estimate {{C}}/{d} --out {{O}}/fit --film-ior 1.4 --quiet")

# capture.json: huge sparse, NUL bytes, a number with 100 000 digits, BOM, cube path tricks.
d = "capture/sparse"
sparse_file(f"{d}/capture.json", capture_json(OK_ANGLES))
case("capture_sparse", "fail:capture.json", f"estimate {{C}}/{d} --out {{O}}/fit --quiet")
capture_case("nul_bytes", capture_json(OK_ANGLES).replace('"s"', '"s\\u0000"'), "fail:capture.json|polarization")
capture_case("long_number", capture_json(OK_ANGLES).replace('"ambient_ior": 1.0', '"ambient_ior": 1' + "0" * 100000),
             "fail:capture.json")
capture_case("bom", "\ufeff" + capture_json(OK_ANGLES), "fail:capture.json")
capture_case("cube_absolute_dev", capture_json([(20, "/dev/zero")]), "fail:/dev/zero")
capture_case("cube_self", capture_json([(20, "capture.json")]), "fail:capture.json")
capture_case("angles_object", capture_json(OK_ANGLES).replace('"angles": [', '"angles": {"a": [').replace("]\n}", "]}\n}"),
             "fail:capture.json")

# Point spectra (`estimate --spectra`): the 2-column text files.
SPEC_OK = "".join(f"{400 + 5 * i} {0.1 + 0.05 * ((i * 7) % 5)}\n" for i in range(60))
SPECTRA = {
    "ok.csv": SPEC_OK,
    "empty.csv": "",
    "one_column.csv": "".join(f"{400 + 5 * i}\n" for i in range(60)),
    "text.csv": "wavelength,intensity\nfoo,bar\n",
    "nan.csv": SPEC_OK.replace("400 ", "nan "),
    "inf_value.csv": SPEC_OK.replace("\n", " \n").replace(" 0.1 ", " inf ", 1),
    "descending.csv": "".join(reversed(SPEC_OK.splitlines(True))),
    "duplicate.csv": SPEC_OK + SPEC_OK.splitlines(True)[-1],
    "binary.csv": bytes(range(256)) * 8,
    "truncated.csv": SPEC_OK[: len(SPEC_OK) // 2] + "5",
    "single_line.csv": "500 0.3\n",
    "huge_wavelength.csv": SPEC_OK.replace("400 ", "1e300 "),
    "many_columns.csv": SPEC_OK.replace("\n", " 1 2 3\n"),
    "long_line.csv": "400 " + "9" * 1000000 + "\n" + SPEC_OK,
    "semicolons.csv": SPEC_OK.replace(" ", ";"),
}
for name, text in SPECTRA.items():
    write(f"spectra/{name}", text)
sparse_file("spectra/sparse.csv", SPEC_OK)
for name in list(SPECTRA) + ["sparse.csv"]:
    stem = name.split(".")[0]
    # Extra columns and ';' separators are read as the 2-column format; a non-finite
    # intensity is masked like a NaN pixel of a cube.
    expect = "ok" if name in ("ok.csv", "many_columns.csv", "semicolons.csv", "inf_value.csv") else f"fail:{name}"
    case(f"spectra_{stem}", expect,
         f"estimate --spectra {{C}}/spectra/{name} {{C}}/spectra/ok.csv --film-ior 1.33 --out {{O}}/fit --quiet")
case("spectra_dark_empty", "fail:empty.csv",
     "estimate --spectra {C}/spectra/ok.csv --dark {C}/spectra/empty.csv --film-ior 1.33 --out {O}/fit --quiet")
case("spectra_dark_other_grid", "fail:single_line.csv",
     "estimate --spectra {C}/spectra/ok.csv --dark {C}/spectra/single_line.csv --film-ior 1.33 --out {O}/fit --quiet")
case("spectra_directory", "fail:spectra",
     "estimate --spectra {C}/spectra --film-ior 1.33 --out {O}/fit --quiet")

# Mitsuba XML: zero-length and sparse scene and include, deep nesting inside an include,
# entity tricks, an include of a binary mesh, single-object include roots (legal).
xml_case("sparse_scene", xml_scene(SPHERE), "fail:sparse_scene.xml")
sparse.append(("xml/sparse_scene.xml", GIB3))
xml_case("truncated_mid_tag", xml_scene(SPHERE)[:-20], "fail:truncated_mid_tag.xml")
xml_case("nul_byte", xml_scene(SPHERE).replace("<shape", "<sh\0ape"), "fail:nul_byte.xml")
xml_case("external_entity", '<?xml version="1.0"?><!DOCTYPE s [<!ENTITY x SYSTEM "/etc/passwd">]>'
         + xml_scene(SPHERE).replace("</scene>", "&x;</scene>"), "fail:external_entity.xml")
xml_case("attr_huge", xml_scene(SPHERE.replace('value="1"', 'value="' + "1" * 2000000 + '"')), "fail:attr_huge.xml|radius")
xml_case("many_shapes", xml_scene(SPHERE * 20000), "ok")
xml_case("transform_chain", xml_scene('<shape type="sphere"><transform name="to_world">'
                                      + '<scale value="10"/>' * 400 + "</transform></shape>"), "fail:transform_chain.xml")
xml_case("lookat_degenerate", xml_scene(SPHERE, SENSOR.replace('origin="0,0,5"', 'origin="0,0,0"')),
         "fail:lookat_degenerate.xml|lookat")
xml_case("film_width_4g", xml_scene(SPHERE, SENSOR.replace('name="width" value="8"', 'name="width" value="4000000000"')),
         "fail:film_width_4g.xml|width")
xml_case("ply_shape_is_obj", xml_scene('<shape type="ply"><string name="filename" value="../obj/ok.obj"/></shape>'),
         "fail:ok.obj")
xml_case("obj_shape_is_glb", xml_scene('<shape type="obj"><string name="filename" value="../gltf/ok.glb"/></shape>'),
         "fail:ok.glb")

include_case("empty_file", {"main.xml": xml_scene(SPHERE + INC.format("e.xml")), "e.xml": ""}, "fail:e.xml")
include_case("sparse_file", {"main.xml": xml_scene(SPHERE + INC.format("big.xml")),
                             "big.xml": "<scene version='3.0.0'>" + SPHERE + "</scene>"}, "fail:big.xml")
sparse.append(("include/sparse_file/big.xml", GIB3))
include_case("deep_nesting_inside", {"main.xml": xml_scene(SPHERE + INC.format("n.xml")),
                                     "n.xml": "<scene version='3.0.0'>" + "<shape type='sphere'>" * 5000
                                     + "</shape>" * 5000 + "</scene>"}, "fail:n.xml")
include_case("object_root_ref", {"main.xml": xml_scene(INC.format("m.xml") + '<shape type="sphere"><ref id="m"/></shape>'),
                                 "m.xml": '<bsdf version="3.0.0" type="conductor" id="m"/>'}, "ok")
include_case("object_root_nested", {"main.xml": xml_scene('<shape type="sphere">' + INC.format("sub/m.xml") + "</shape>"),
                                    "sub/m.xml": '<bsdf version="3.0.0" type="twosided">' + INC.format("inner.xml") + "</bsdf>",
                                    "sub/inner.xml": '<bsdf version="3.0.0" type="diffuse"/>'}, "ok")
include_case("object_root_v1", {"main.xml": xml_scene(INC.format("s.xml")),
                                "s.xml": '<shape version="0.6.0" type="sphere"><bsdf type="diffuse">'
                                '<rgb name="reflectance" value="0.5"/></bsdf></shape>'}, "ok")
include_case("object_root_no_version", {"main.xml": xml_scene(SPHERE + INC.format("m.xml")),
                                        "m.xml": '<bsdf type="diffuse"/>'}, "fail:m.xml|version")
include_case("scene_root_no_version", {"main.xml": xml_scene(SPHERE + INC.format("s.xml")),
                                       "s.xml": "<scene>" + SPHERE + "</scene>"}, "fail:s.xml|version")
include_case("property_root", {"main.xml": xml_scene('<shape type="sphere">' + INC.format("p.xml") + "</shape>"),
                               "p.xml": '<float version="3.0.0" name="radius" value="2"/>'}, "fail:p.xml|version")
include_case("dot_path_cycle", {"main.xml": xml_scene(SPHERE + INC.format("./sub/../main.xml"))}, "fail:cycle")
include_case("a_mesh", {"main.xml": xml_scene(SPHERE + INC.format("m.ply")),
                        "m.ply": ply_ascii(3, 1, TRI_V, TRI_F)}, "fail:m.ply|malformed")

# PLY: lying counts in binary and ASCII, big-endian, odd property types, overflowing lists.
PLY_BIN_HEAD = ("ply\nformat binary_{end}_endian 1.0\nelement vertex {nv}\nproperty {t} x\nproperty {t} y\n"
                "property {t} z\nelement face {nf}\nproperty list {ct} {it} vertex_indices\nend_header\n")


def ply_bin(nv=3, nf=1, end="little", t="float", ct="uchar", it="int", verts=None, faces=None):
    e = "<" if end == "little" else ">"
    fc = {"float": "f", "double": "d", "uchar": "B", "int": "i", "uint": "I", "short": "h", "char": "b"}
    if verts is None:
        verts = struct.pack(e + "9" + fc[t], 0, 0, 0, 1, 0, 0, 0, 1, 0)
    if faces is None:
        faces = struct.pack(e + fc[ct], 3) + struct.pack(e + "3" + fc[it], 0, 1, 2)
    return PLY_BIN_HEAD.format(end=end, nv=nv, t=t, nf=nf, ct=ct, it=it).encode() + verts + faces


mesh_case("bin_ok", "ply", ply_bin(), "ok")
mesh_case("bin_big_endian", "ply", ply_bin(end="big"), "ok")
mesh_case("bin_double", "ply", ply_bin(t="double"), "ok")
mesh_case("bin_fewer_vertices_than_said", "ply", ply_bin(nv=5), "fail:bin_fewer_vertices_than_said.ply")
mesh_case("bin_more_faces_than_said", "ply", ply_bin(nf=1000), "fail:bin_more_faces_than_said.ply")
mesh_case("bin_face_count_u32_max", "ply", ply_bin(nf=2**32 - 1), "fail:bin_face_count_u32_max.ply")
mesh_case("bin_list_count_255", "ply", ply_bin(faces=struct.pack("<B", 255) + struct.pack("<3i", 0, 1, 2)),
          "fail:bin_list_count_255.ply")
mesh_case("bin_index_negative", "ply", ply_bin(faces=struct.pack("<B", 3) + struct.pack("<3i", 0, 1, -2147483648)),
          "fail:bin_index_negative.ply")
mesh_case("bin_index_uint_max", "ply", ply_bin(it="uint", faces=struct.pack("<B", 3) + struct.pack("<3I", 0, 1, 2**32 - 1)),
          "fail:bin_index_uint_max.ply")
mesh_case("bin_short_coords", "ply", ply_bin(t="short", verts=struct.pack("<9h", 0, 0, 0, 1, 0, 0, 0, 1, 0)), "ok")
mesh_case("bin_vertex_count_negative", "ply", ply_bin(nv=-1), "fail:bin_vertex_count_negative.ply")
mesh_case("zero_vertices_faces", "ply", ply_ascii(0, 1, [], TRI_F), "fail:zero_vertices_faces.ply")
mesh_case("header_only", "ply", ply_ascii(3, 1, [], []), "fail:header_only.ply")
mesh_case("header_huge_comment", "ply", ply_ascii(3, 1, TRI_V, TRI_F).replace(
    "format ascii 1.0\n", "format ascii 1.0\ncomment " + "x" * 5000000 + "\n"), "ok")
mesh_case("header_10k_properties", "ply", ply_ascii(3, 1, TRI_V, TRI_F).replace(
    "property float z\n", "property float z\n" + "".join(f"property float p{i}\n" for i in range(10000))),
    "fail:header_10k_properties.ply")
mesh_case("ascii_lying_faces", "ply", ply_ascii(3, 5, TRI_V, TRI_F), "fail:ascii_lying_faces.ply")
sparse_file("ply/sparse.ply", ply_bin(nv=2**28, nf=1, verts=b"", faces=b""))
case("ply_sparse", "fail:sparse.ply", "render {C}/ply/sparse.ply -o {O}/out.exr --spp 1 --resolution 8x8")
mesh_case("truncated_header", "ply", "ply\nformat ascii 1.0\nelement vert", "fail:truncated_header.ply")

# OBJ: more bad indices and lines.
V3 = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"
for cid, text, expect in [
    ("relative_ok", V3 + "f -3 -2 -1\n", "ok"),
    ("index_i64_min", V3 + "f 1 2 -9223372036854775808\n", "fail:index_i64_min.obj"),
    ("index_slashes_only", V3 + "f / / /\n", "fail:index_slashes_only.obj"),
    ("index_empty_fields", V3 + "f 1// 2// 3//\n", "ok"),
    ("face_two_vertices", V3 + "f 1 2\n", "fail:face_two_vertices.obj"),
    ("face_text", V3 + "f a b c\n", "fail:face_text.obj"),
    ("vertex_one_coordinate", "v 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", "fail:vertex_one_coordinate.obj"),
    ("vt_nan", V3 + "vt nan 0\nf 1/1 2/1 3/1\n", "fail:vt_nan.obj"),
    ("vn_zero", V3 + "vn 0 0 0\nf 1//1 2//1 3//1\n", "ok"),
    ("long_line", V3 + "# " + "x" * 5000000 + "\nf 1 2 3\n", "ok"),
    ("nul_bytes", V3.replace("v 1", "v \0 1") + "f 1 2 3\n", "fail:nul_bytes.obj"),
    ("crlf", (V3 + "f 1 2 3\n").replace("\n", "\r\n"), "ok"),
    ("usemtl_no_lib", "usemtl red\n" + V3 + "f 1 2 3\n", "ok"),
    ("only_groups", "o a\ng b\ns 1\n", "fail:only_groups.obj"),
]:
    mesh_case(cid, "obj", text, expect)
write("obj/bad_mtl.mtl", "newmtl m\nKd nan banana\nNs 1e400\nmap_Kd /dev/zero\n")
mesh_case("mtl_garbage", "obj", "mtllib bad_mtl.mtl\nusemtl m\n" + V3 + "f 1 2 3\n", "ok")
sparse_file("obj/sparse.obj", V3 + "f 1 2 3\n")
case("obj_sparse", "fail:sparse.obj", "render {C}/obj/sparse.obj -o {O}/out.exr --spp 1 --resolution 8x8")

# glTF / GLB: more accessor, view and URI cases.
g = gltf_doc()
mod(g, ["accessors", 0, "byteOffset"], 2**63)
gltf_case("accessor_offset_i64", g, "fail:accessor_offset_i64.gltf")
g = gltf_doc()
mod(g, ["accessors", 1, "count"], 2**53)
gltf_case("indices_count_2_53", g, "fail:indices_count_2_53.gltf")
g = gltf_doc()
mod(g, ["accessors", 0, "count"], 0)
gltf_case("position_count_zero", g, "fail:position_count_zero.gltf")
g = gltf_doc()
mod(g, ["bufferViews", 0, "byteStride"], 2**31)
gltf_case("stride_2_31", g, "fail:stride_2_31.gltf")
g = gltf_doc()
g["buffers"] = [{"byteLength": len(BUF), "uri": "data:application/octet-stream;base64," + "A" * 5}]
gltf_case("data_uri_bad_length", g, "fail:data_uri_bad_length.gltf")
g = gltf_doc()
g["buffers"] = [{"byteLength": len(BUF), "uri": "data:application/octet-stream," + "x" * 64}]
gltf_case("data_uri_not_base64", g, "fail:data_uri_not_base64.gltf")
g = gltf_doc()
g["buffers"] = [{"byteLength": 2**40, "uri": data_uri(BUF)}]
gltf_case("data_uri_declares_1tb", g, "fail:data_uri_declares_1tb.gltf")
g = gltf_doc()
g["buffers"] = [{"byteLength": len(BUF), "uri": "../../../../../../dev/zero"}]
gltf_case("buffer_dev_zero", g, "fail:buffer_dev_zero.gltf")
g = gltf_doc()
g["buffers"] = [{"byteLength": 2**31, "uri": "sparse.bin"}]
sparse_file("gltf/sparse.bin", BUF, 2**31)
gltf_case("buffer_sparse_2gb", g, "fail:buffer_sparse_2gb.gltf")
g = gltf_doc()
g["nodes"] = [{"mesh": 0, "children": [1]}, {"children": [2]}, {"children": [0]}]
gltf_case("cycle_three", g, "fail:cycle_three.gltf")
g = gltf_doc()
g["nodes"] = [{"mesh": 0, "children": list(range(1, 5001))}] + [{"mesh": 0} for _ in range(5000)]
gltf_case("wide_tree", g, "ok")
g = gltf_doc()
g["nodes"] = [{"mesh": 0, "children": [i + 1]} if i < 3000 else {"mesh": 0} for i in range(3001)]
gltf_case("deep_chain", g, "ok")
g = gltf_doc()
g["extensionsRequired"] = ["KHR_draco_mesh_compression"]
g["extensionsUsed"] = ["KHR_draco_mesh_compression"]
gltf_case("extension_required_unknown", g, "fail:extension_required_unknown.gltf|KHR_draco_mesh_compression")
g = gltf_doc()
g["nodes"] = [{"mesh": 0, "scale": [1e30, 1e30, 1e30], "translation": [1e38, 0, 0]}]
gltf_case("node_far_away", g, "fail:node_far_away.gltf")
g = gltf_doc()
g["nodes"] = [{"mesh": 0, "rotation": [0, 0, 0, 0]}]
gltf_case("rotation_zero_quat", g, "ok")  # all vertices at the origin: nothing to hit
g = gltf_doc()
g["meshes"] = [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1, "targets": [{"POSITION": 7}]}]}]
gltf_case("morph_target_out_of_range", g, "fail:morph_target_out_of_range.gltf")
g = gltf_doc()
g["meshes"] = [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}] * 20000}]
gltf_case("many_primitives", g, "ok")
g = gltf_doc()
g["images"] = [{"uri": data_uri(b"\x89PNG\r\n\x1a\n" + bytes(64))}]
g["textures"] = [{"source": 0}]
g["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
g["meshes"][0]["primitives"][0]["material"] = 0
gltf_case("image_data_uri_garbage", g, "fail:image_data_uri_garbage.gltf")
g = gltf_doc()
g["images"] = [{"uri": data_uri(png_bytes(1, 1, raw=b"\0" * (20000 * 3 + 1) * 200, declared=(20000, 20000)))}]
g["textures"] = [{"source": 0}]
g["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
g["meshes"][0]["primitives"][0]["material"] = 0
gltf_case("image_data_uri_bomb", g, "fail:image_data_uri_bomb.gltf")
g = gltf_doc()
g["samplers"] = [{"wrapS": 1}]
g["textures"] = [{"source": 0, "sampler": 9}]
gltf_case("sampler_out_of_range", g, "fail:sampler_out_of_range.gltf")
g = gltf_doc()
g["accessors"][0]["sparse"] = {"count": 2**31, "indices": {"bufferView": 1, "componentType": 5123},
                               "values": {"bufferView": 0}}
gltf_case("sparse_count_huge", g, "fail:sparse_count_huge.gltf")
gltf_case("zero_length", None, "fail:zero_length.gltf", raw="")
gltf_case("truncated", None, "fail:truncated.gltf", raw=json.dumps(gltf_doc())[:100])
gltf_case("json_nul", None, "fail:json_nul.gltf", raw=json.dumps(gltf_doc()).replace('"2.0"', '"2.0\0"'))
sparse_file("gltf/sparse.gltf", json.dumps(gltf_doc()))
case("gltf_sparse", "fail:sparse.gltf", "render {C}/gltf/sparse.gltf -o {O}/out.exr --spp 1 --resolution 8x8")
for cid, data, expect in [
    ("zero_length", b"", "fail:zero_length.glb"),
    ("header_only", b"glTF" + struct.pack("<II", 2, 12), "fail:header_only.glb"),
    ("version_1", b"glTF" + struct.pack("<II", 1, 20) + bytes(8), "fail:version_1.glb"),
    ("json_chunk_odd", glb(json.dumps(glb_doc), BUF, json_len=7), "fail:json_chunk_odd.glb"),
    ("bin_short_for_views", glb(json.dumps(glb_doc), BUF[:12]), "fail:bin_short_for_views.glb"),
    ("total_len_small", glb(json.dumps(glb_doc), BUF, total_len=20), "fail:total_len_small.glb"),
    ("json_garbage", glb("{ not json", BUF), "fail:json_garbage.glb"),
]:
    rel = write(f"gltf/{cid}.glb", data)
    case(f"glb_{cid}", expect, f"render {{C}}/{rel} -o {{O}}/out.exr --spp 1 --resolution 8x8")
sparse_file("gltf/sparse.glb", glb(json.dumps(glb_doc), BUF, total_len=GIB3))
case("glb_sparse", "fail:sparse.glb", "render {C}/gltf/sparse.glb -o {O}/out.exr --spp 1 --resolution 8x8")

# Textures: zero-length and sparse files of each image format, truncated HDR.
TEX = {
    "zero.png": b"",
    "zero.jpg": b"",
    "zero.hdr": b"",
    "zero.exr": b"",
    "png_16bit.png": b"\x89PNG\r\n\x1a\n" + png_chunk(b"IHDR", struct.pack(">IIBBBBB", 2, 2, 16, 2, 0, 0, 0))
    + png_chunk(b"IDAT", zlib.compress(b"".join(b"\0" + b"\x80\x00" * 6 for _ in range(2)))) + png_chunk(b"IEND", b""),
    "png_idat_short.png": png_bytes(4, 4, raw=b"\0" * 5),
    "png_crc_bad.png": png_bytes(4, 4)[:-5] + b"\x00" + png_bytes(4, 4)[-4:],
    "hdr_truncated.hdr": b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 64 +X 64\n" + b"\x02\x02\x00\x40" + b"\x80" * 10,
    "hdr_no_size.hdr": b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n",
    "hdr_negative.hdr": b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y -5 +X 4\n" + b"\0" * 64,
    "hdr_rle_overrun.hdr": b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 1 +X 16\n" + b"\x02\x02\x00\x10"
    + (b"\xff\x80") * 64,
    "jpeg_sof_zero.jpg": jpeg_sof(0, 0),
}
for name, data in TEX.items():
    write(f"tex/{name}", data)
sparse_file("tex/sparse.png", png_bytes(4, 4))
sparse_file("tex/sparse.exr", exr_bytes(4, 2))
sparse_file("tex/sparse.hdr", b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 4 +X 4\n")
for name in list(TEX) + ["sparse.png", "sparse.exr", "sparse.hdr"]:
    stem = name.replace(".", "_")
    # Decoders read what the header declares: a valid image followed by a hole loads, and
    # the PNG decoder does not check CRCs.
    ok_tex = name in ("png_16bit.png", "png_crc_bad.png", "sparse.png", "sparse.exr", "sparse.hdr")
    rel = write(f"xml/tex_{stem}.xml", xml_scene(
        '<shape type="sphere"><bsdf type="diffuse"><texture type="bitmap" name="reflectance">'
        f'<string name="filename" value="../tex/{name}"/></texture></bsdf></shape>'))
    case(f"tex_bitmap_{stem}", "ok" if ok_tex else f"fail:{name}", f"render {{C}}/{rel} -o {{O}}/out.exr")
    if name.endswith((".exr", ".hdr")):
        rel = write(f"xml/env_{stem}.xml", xml_scene(
            SPHERE + f'<emitter type="envmap"><string name="filename" value="../tex/{name}"/></emitter>'))
        case(f"tex_envmap_{stem}", "ok" if ok_tex else f"fail:{name}", f"render {{C}}/{rel} -o {{O}}/out.exr")

# `figure FITDIR`: the fit folder's fit.json and thickness map.
FIG = "figure {{C}}/fit/{d} --capture {{C}}/capture_ok --resolution 8 --spp 1 --out {{O}}/fig.png"
for d, files, expect in [
    ("empty_dir", {"x.txt": "x"}, "fail:fit.json"),
    ("fit_empty", {"fit.json": ""}, "fail:fit.json"),
    ("fit_not_json", {"fit.json": "{ nope"}, "fail:fit.json"),
    ("fit_wrong_format", {"fit.json": json.dumps({"format": "thinfilm-fit/99"})}, "fail:fit.json"),
    ("fit_array", {"fit.json": "[]"}, "fail:fit.json"),
    ("fit_deep", {"fit.json": "[" * 50000 + "]" * 50000}, "fail:fit.json"),
    ("fit_binary", {"fit.json": bytes(range(256))}, "fail:fit.json"),
]:
    for name, text in files.items():
        write(f"fit/{d}/{name}", text)
    case(f"figure_{d}", expect, FIG.format(d=d))
write("fit/fit_sparse/fit.json", "{}")
sparse.append(("fit/fit_sparse/fit.json", GIB3))
case("figure_fit_sparse", "fail:fit.json", FIG.format(d="fit_sparse"))
case("figure_fit_dir_missing", "fail:nope", FIG.format(d="nope"))
case("figure_resolution_huge", "fail:--resolution",
     "figure --samples --resolution 4000000000 --out {O}/fig.png")
case("figure_spp_zero", "fail:--spp", "figure --samples --spp 0 --resolution 8 --out {O}/fig.png")

# `merge`: zero-length and sparse pieces, a PNG given as a piece, one piece twice.
write("merge_extra/zero.exr", b"")
sparse_file("merge_extra/sparse.exr", exr_bytes(4, 2))
write("merge_extra/a_png.exr", png_bytes(4, 4))
for cid, pieces, expect in [
    ("zero_length", "{C}/merge_extra/zero.exr {C}/merge_extra/zero.exr", "fail:zero.exr"),
    ("sparse_piece", "{C}/merge_extra/sparse.exr {C}/merge_extra/sparse.exr", "fail:sparse.exr"),
    ("png_as_exr", "{C}/merge_extra/a_png.exr {C}/merge_extra/a_png.exr", "fail:a_png.exr"),
    ("one_piece", "{C}/merge_extra/zero.exr", "fail:"),
]:
    case(f"merge_{cid}", expect, f"merge {pieces} -o {{O}}/merged.exr")

# `compare`: sparse and zero-length images.
case("compare_sparse", "ok", "compare {C}/tex/sparse.exr {C}/exr/ok.exr")
case("compare_png_zero", "fail:zero.png", "compare {C}/tex/zero.png {C}/exr/ok.exr")


# -------------------------------------------------------------------------------- manifest

with open(os.path.join(OUT, "cases.txt"), "w") as f:
    f.write("# Hostile-input cases: ID<TAB>EXPECT<TAB>ARGS (written by tools/hostile/make_corpus.py)\n")
    for path, n in sparse:
        f.write(f"@sparse {path} {n}\n")
    for cid, expect, args in cases:
        f.write(f"{cid}\t{expect}\t{args}\n")
print(f"{len(cases)} cases, {len(sparse)} sparse files in {OUT}")
