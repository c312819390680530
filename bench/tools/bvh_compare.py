#!/usr/bin/env python3
"""Independent BVH reader to check `kinemo bvh convert` (stdlib only).

Compare two BVH files (same joints, channel lists, frame count and frame
time; channel values and offsets within a tolerance):

    bench/tools/bvh_compare.py A.bvh B.bvh [--tol 1e-4]

Check the verification interface over every BVH under a directory: run
`KINEMO bvh convert IN -o OUT` for each file, then compare IN and OUT:

    bench/tools/bvh_compare.py --all [--data ../shared/data/motion]
                               [--kinemo build/services/cli/kinemo] [--tol 1e-4]

Without --kinemo the script looks for the `kinemo` binary under build*/
(as the verification interface does), then for `kinemo_bvh_tool` (the same
`bvh` commands built by tests/unit/motion).

Exit status: 0 all good; 1 a difference above the tolerance or a conversion
that failed on a valid input; 2 usage or input error (single-file mode).
This reader shares no code with kinemo's C++ reader.
"""

import argparse
import math
import os
import subprocess
import sys
import tempfile


class BvhError(Exception):
    pass


class Bvh:
    def __init__(self):
        self.joints = []  # (name, parent, offset, channels, end_site)
        self.frame_time = None
        self.frames = []  # list of lists of floats

    @property
    def num_channels(self):
        return sum(len(j[3]) for j in self.joints)


def _number(tok, what, path):
    try:
        v = float(tok)
    except ValueError:
        raise BvhError(f"{path}: {what}: not a number: {tok!r}")
    if not math.isfinite(v):
        raise BvhError(f"{path}: {what}: not finite: {tok!r}")
    return v


def read_bvh(path):
    """Parses a BVH file into a Bvh; raises BvhError on malformed input."""
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as e:
        raise BvhError(f"{path}: cannot read: {e}")
    if not data.strip():
        raise BvhError(f"{path}: empty file")
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError:
        raise BvhError(f"{path}: not UTF-8 text")
    head, sep, motion = text.partition("MOTION")
    if not sep:
        raise BvhError(f"{path}: no MOTION section")
    toks = head.split()
    if not toks or toks[0] != "HIERARCHY":
        raise BvhError(f"{path}: does not start with HIERARCHY")
    bvh = Bvh()
    stack = []  # indices of open joints; None for an open End Site
    i = 1
    n = len(toks)

    def need(k):
        if i + k > n:
            raise BvhError(f"{path}: hierarchy ends early")

    while i < n:
        t = toks[i]
        if t in ("ROOT", "JOINT"):
            need(2)
            name = toks[i + 1]
            parent = stack[-1] if stack else -1
            if t == "JOINT" and (parent == -1 or parent is None):
                raise BvhError(f"{path}: JOINT {name} outside a joint")
            bvh.joints.append([name, parent, None, [], None])
            i += 2
            need(1)
            if toks[i] != "{":
                raise BvhError(f"{path}: expected '{{' after {t} {name}")
            stack.append(len(bvh.joints) - 1)
            i += 1
        elif t == "End":
            need(8)
            if toks[i + 1] != "Site" or toks[i + 2] != "{" or toks[i + 3] != "OFFSET" or toks[i + 7] != "}":
                raise BvhError(f"{path}: malformed End Site")
            if not stack or stack[-1] is None:
                raise BvhError(f"{path}: End Site outside a joint")
            bvh.joints[stack[-1]][4] = [_number(x, "End Site OFFSET", path) for x in toks[i + 4:i + 7]]
            i += 8
        elif t == "OFFSET":
            need(4)
            if not stack:
                raise BvhError(f"{path}: OFFSET outside a joint")
            bvh.joints[stack[-1]][2] = [_number(x, "OFFSET", path) for x in toks[i + 1:i + 4]]
            i += 4
        elif t == "CHANNELS":
            need(2)
            try:
                k = int(toks[i + 1])
            except ValueError:
                raise BvhError(f"{path}: bad CHANNELS count {toks[i + 1]!r}")
            if not 0 <= k <= 6:
                raise BvhError(f"{path}: CHANNELS {k} out of range")
            need(2 + k)
            names = toks[i + 2:i + 2 + k]
            for c in names:
                if c.lower() not in ("xposition", "yposition", "zposition",
                                     "xrotation", "yrotation", "zrotation"):
                    raise BvhError(f"{path}: unknown channel {c!r}")
            bvh.joints[stack[-1]][3] = names
            i += 2 + k
        elif t == "}":
            if not stack:
                raise BvhError(f"{path}: unbalanced '}}'")
            stack.pop()
            i += 1
        else:
            raise BvhError(f"{path}: unexpected token {t!r} in hierarchy")
    if stack:
        raise BvhError(f"{path}: unbalanced braces ({len(stack)} open)")
    if not bvh.joints:
        raise BvhError(f"{path}: no joints")
    for j in bvh.joints:
        if j[2] is None:
            raise BvhError(f"{path}: joint {j[0]} has no OFFSET")

    lines = motion.splitlines()
    # lines[0] is the rest of the MOTION line.
    rest = [ln for ln in lines[1:]]
    pos = 0

    def next_nonblank():
        nonlocal pos
        while pos < len(rest) and not rest[pos].strip():
            pos += 1
        if pos >= len(rest):
            raise BvhError(f"{path}: motion header ends early")
        ln = rest[pos]
        pos += 1
        return ln

    fl = next_nonblank().split()
    if len(fl) != 2 or fl[0] != "Frames:":
        raise BvhError(f"{path}: expected 'Frames: N'")
    try:
        num_frames = int(fl[1])
    except ValueError:
        raise BvhError(f"{path}: bad frame count {fl[1]!r}")
    if num_frames < 0:
        raise BvhError(f"{path}: negative frame count")
    tl = next_nonblank().split()
    if len(tl) != 3 or tl[0] != "Frame" or tl[1] != "Time:":
        raise BvhError(f"{path}: expected 'Frame Time: T'")
    bvh.frame_time = _number(tl[2], "Frame Time", path)
    if bvh.frame_time <= 0:
        raise BvhError(f"{path}: Frame Time must be positive")
    nc = bvh.num_channels
    for ln in rest[pos:]:
        if not ln.strip():
            continue
        vals = ln.split()
        if len(vals) != nc:
            raise BvhError(f"{path}: frame {len(bvh.frames)} has {len(vals)} values, expected {nc}")
        bvh.frames.append([_number(v, f"frame {len(bvh.frames)}", path) for v in vals])
    if len(bvh.frames) != num_frames:
        raise BvhError(f"{path}: {len(bvh.frames)} frames, header says {num_frames}")
    return bvh


def compare(a, b):
    """Returns (max_abs_diff, problems) between two parsed BVHs."""
    problems = []
    if [j[0] for j in a.joints] != [j[0] for j in b.joints]:
        problems.append("joint names/order differ")
    if [j[1] for j in a.joints] != [j[1] for j in b.joints]:
        problems.append("parents differ")
    if [j[3] for j in a.joints] != [j[3] for j in b.joints]:
        problems.append("channel lists differ")
    if len(a.frames) != len(b.frames):
        problems.append(f"frame counts differ: {len(a.frames)} vs {len(b.frames)}")
    if abs(a.frame_time - b.frame_time) > 1e-9 * max(1.0, a.frame_time):
        problems.append(f"frame times differ: {a.frame_time} vs {b.frame_time}")
    worst = 0.0
    same_shape = ([j[3] for j in a.joints] == [j[3] for j in b.joints]
                  and len(a.joints) == len(b.joints) and len(a.frames) == len(b.frames))
    if same_shape:
        for ja, jb in zip(a.joints, b.joints):
            worst = max(worst, max(abs(x - y) for x, y in zip(ja[2], jb[2])))
            if (ja[4] is None) != (jb[4] is None):
                problems.append(f"End Site of {ja[0]} differs")
            elif ja[4] is not None:
                worst = max(worst, max(abs(x - y) for x, y in zip(ja[4], jb[4])))
        for fa, fb in zip(a.frames, b.frames):
            for x, y in zip(fa, fb):
                d = abs(x - y)
                if d > worst:
                    worst = d
    return worst, problems


def find_kinemo():
    root = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    found = []
    for name in ("kinemo", "kinemo_bvh_tool"):
        for entry in sorted(os.listdir(root)):
            if not entry.startswith("build"):
                continue
            for dirpath, _, files in os.walk(os.path.join(root, entry)):
                if name in files:
                    p = os.path.join(dirpath, name)
                    if os.access(p, os.X_OK) and os.path.isfile(p):
                        found.append(p)
        if found:
            return found[0]
    return None


def run_all(args):
    kinemo = args.kinemo or find_kinemo()
    if not kinemo:
        print("no kinemo binary found (pass --kinemo)", file=sys.stderr)
        return 2
    files = []
    for dirpath, _, names in os.walk(args.data):
        files += [os.path.join(dirpath, n) for n in names if n.lower().endswith(".bvh")]
    files.sort()
    if not files:
        print(f"no .bvh files under {args.data}", file=sys.stderr)
        return 2
    print(f"kinemo: {kinemo}\ndata:   {args.data} ({len(files)} BVH files)\ntol:    {args.tol}")
    n_ok = n_input_err = n_fail = 0
    overall = 0.0
    with tempfile.TemporaryDirectory(prefix="bvh_compare_") as tmp:
        for k, path in enumerate(files):
            rel = os.path.relpath(path, args.data)
            out = os.path.join(tmp, f"{k}.bvh")
            proc = subprocess.run([kinemo, "bvh", "convert", path, "-o", out],
                                  capture_output=True, text=True, timeout=300)
            try:
                ref = read_bvh(path)
            except BvhError as e:
                ref, ref_err = None, str(e)
            if ref is None:
                if proc.returncode != 0 and proc.returncode < 128:
                    n_input_err += 1
                    print(f"INPUT ERROR  {rel}: reference reader: {ref_err}; "
                          f"kinemo (exit {proc.returncode}): {proc.stderr.strip()}")
                else:
                    n_fail += 1
                    print(f"FAIL         {rel}: invalid input accepted or crashed "
                          f"(exit {proc.returncode}): {ref_err}")
                continue
            if proc.returncode != 0:
                n_fail += 1
                print(f"FAIL         {rel}: kinemo exit {proc.returncode}: {proc.stderr.strip()}")
                continue
            try:
                got = read_bvh(out)
            except BvhError as e:
                n_fail += 1
                print(f"FAIL         {rel}: output unreadable: {e}")
                continue
            worst, problems = compare(ref, got)
            overall = max(overall, worst)
            if problems or worst > args.tol:
                n_fail += 1
                print(f"FAIL         {rel}: max diff {worst:.3g} {'; '.join(problems)}")
            else:
                n_ok += 1
                if args.verbose:
                    print(f"ok           {rel}: {len(ref.joints)} joints, {len(ref.frames)} frames, "
                          f"max diff {worst:.3g}")
    print(f"\nsummary: {n_ok} round-tripped within {args.tol} (max diff {overall:.3g}), "
          f"{n_input_err} invalid inputs rejected by both readers, {n_fail} failures")
    return 1 if n_fail else 0


def main():
    repo = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("files", nargs="*", help="two BVH files to compare")
    ap.add_argument("--all", action="store_true", help="convert and compare every BVH under --data")
    ap.add_argument("--data", default=os.path.join(os.path.dirname(repo), "shared", "data", "motion"))
    ap.add_argument("--kinemo", help="path of the kinemo (or kinemo_bvh_tool) binary")
    ap.add_argument("--tol", type=float, default=1e-4)
    ap.add_argument("-v", "--verbose", action="store_true")
    args = ap.parse_args()
    if args.all:
        return run_all(args)
    if len(args.files) != 2:
        ap.error("give two files, or --all")
    try:
        a = read_bvh(args.files[0])
        b = read_bvh(args.files[1])
    except BvhError as e:
        print(f"input error: {e}", file=sys.stderr)
        return 2
    worst, problems = compare(a, b)
    for p in problems:
        print(f"mismatch: {p}")
    print(f"max abs difference: {worst:.6g} ({len(a.joints)} joints, {len(a.frames)} frames)")
    return 0 if not problems and worst <= args.tol else 1


if __name__ == "__main__":
    sys.exit(main())
