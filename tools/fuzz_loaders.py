#!/usr/bin/env python3
"""Mutation fuzzing of lidarsim's loaders through `lidarsim check`.

    tools/fuzz_loaders.py target/release/lidarsim CASES SEED [WORK_DIR]

Each case mutates one of a valid campaign's files (campaign YAML with a sweep, scene YAML, a
heightfield, an OBJ, an instance table, an ASCII and a binary PLY) by byte flips, cuts,
copies and hostile tokens, and runs `lidarsim check` on it. A finding is an exit code other
than 0 or 1, a panic ("internal error"), a rejection without exactly one `error:` line, or a
case over 30 s; each is kept as WORK_DIR/findN. Exits 1 if there is any finding.
"""
import os, random, subprocess, sys, shutil, tempfile
if len(sys.argv) < 4:
    sys.exit(__doc__)
BIN = os.path.abspath(sys.argv[1]); N = int(sys.argv[2]); seed = int(sys.argv[3])
WORK = sys.argv[4] if len(sys.argv) > 4 else tempfile.mkdtemp(prefix="lidarsim_fuzz_")
rng = random.Random(seed)
files = {
 "campaign.yaml": """name: f
scene: scene.yaml
seed: 1
wavelength_nm: 1064
instrument:
  kind: discrete_return
  pulse_energy_j: 0.001
  pulse_fwhm_ns: 3
  footprint_half_angle_mrad: 0.25
  fov_half_angle_mrad: 0.375
  receiver_area_m2: 0.1
  bin_ns: 0.5
  bandwidth_nm: 1.0
  range_gate: { start_ns: 0, bins: 2000 }
platform:
  kind: als
  altitude_m: 100
  speed_m_s: 50
  prf_hz: 1000
  lines: [ { start: [0, 5], end: [10, 5] } ]
  scanner: { pattern: oscillating, scan_angle_deg: [-10, 10], scan_frequency_hz: 20 }
simulation: { method: bdpt, rays_per_pulse: 10, max_order: 3 }
sun: { zenith_deg: 30, azimuth_deg: 0, irradiance_w_m2_um: 600 }
sweep:
  platform.altitude_m: [100, 200]
""",
 "scene.yaml": """name: s
materials:
  soil: { reflectance: { 1064: 0.3, 532: 0.1 } }
  leaf: { reflectance: 0.4, transmittance: 0.4 }
objects:
  - plane: { z: 0, extent: [[0, 0], [10, 10]], material: soil }
  - heightfield: { file: dem.csv, cell_m: 2, origin: [0, 0], material: soil }
  - mesh: { file: tree.obj, materials: { leaves: leaf }, instances: trees.csv }
  - mesh: { file: roof.ply, material: soil, class: building }
""",
 "dem.csv": "# z\n1,2,3\n2,3,4\n3,4,5\n",
 "tree.obj": "g leaves\nv 0 0 1\nv 1 0 1\nv 0 1 1\nv 1 1 2\nf 1 2 3\nf 2 4 3\n",
 "trees.csv": "# x y z rotation scale\n1 2 0 0 1\n3, 4, 0, 90, 1.5\n",
 "roof.ply": "ply\nformat ascii 1.0\nelement vertex 4\nproperty float x\nproperty float y\nproperty float z\nelement face 2\nproperty list uchar int vertex_indices\nend_header\n0 0 5\n1 0 5\n1 1 5\n0 1 5\n3 0 1 2\n3 0 2 3\n",
}
# a binary PLY too
import struct
verts = [(0,0,6),(1,0,6),(1,1,6)]
b = b"ply\nformat binary_little_endian 1.0\nelement vertex 3\nproperty float x\nproperty float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\nend_header\n"
for v in verts: b += struct.pack("<fff", *v)
b += struct.pack("<B", 3) + struct.pack("<iii", 0, 1, 2)
binply = b
TOKENS = [b"-1", b"0", b"1e308", b"nan", b"inf", b"-inf", b"", b"[", b"]", b"{", b"}", b":", b",", b"\n", b"  ", b"\t", b"\"", b"'", b"#", b"99999999999999999999", b"4294967296", b"-0", b"1e-320", b"null", b"~", b"[[]]", b"{a: b}", b"\x00", b"\xff\xfe", b"f 1 2 99", b"v 1 2", b"3 0 1 9", b"element vertex 100000000000\n"]
def mutate(data: bytes) -> bytes:
    d = bytearray(data)
    for _ in range(rng.randint(1, 4)):
        op = rng.randrange(5)
        if not d: d = bytearray(b" ")
        i = rng.randrange(len(d))
        if op == 0: d[i] = rng.randrange(256)
        elif op == 1: del d[i:i + rng.randint(1, 8)]
        elif op == 2: d[i:i] = rng.choice(TOKENS)
        elif op == 3:
            j = rng.randrange(len(d)); d[i:i] = d[j:j + rng.randint(1, 20)]
        else:
            # replace a number-ish run with a token
            j = i
            while j < len(d) and chr(d[j]) in "0123456789.-e": j += 1
            d[i:j] = rng.choice(TOKENS)
    return bytes(d)
names = list(files) + ["bin.ply"]
findings = 0
for n in range(N):
    d = os.path.join(WORK, "case")
    shutil.rmtree(d, ignore_errors=True); os.makedirs(d)
    target = rng.choice(names)
    for k, v in files.items():
        data = v.encode()
        if k == target: data = mutate(data)
        open(os.path.join(d, k), "wb").write(data)
    bp = binply if target != "bin.ply" else mutate(binply)
    open(os.path.join(d, "bin.ply"), "wb").write(bp)
    if target == "bin.ply":
        with open(os.path.join(d, "scene.yaml"), "a") as f:
            f.write("  - mesh: { file: bin.ply, material: soil }\n")
    cmd = [BIN, "check", os.path.join(d, "campaign.yaml")]
    try:
        p = subprocess.run(cmd, capture_output=True, timeout=30)
    except subprocess.TimeoutExpired:
        findings += 1; print("TIMEOUT", target); shutil.copytree(d, os.path.join(WORK, f"find{findings}")); continue
    err = p.stderr.decode(errors="replace")
    errlines = [l for l in err.splitlines() if l.startswith("error:")]
    if p.returncode not in (0, 1) or "internal error" in err or (p.returncode == 1 and len(errlines) != 1):
        findings += 1
        print("FINDING", findings, target, p.returncode, err.strip()[:300])
        shutil.copytree(d, os.path.join(WORK, f"find{findings}"))
print("cases", N, "findings", findings, "in", WORK)
sys.exit(1 if findings else 0)
