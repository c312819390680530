#!/usr/bin/python3
"""Walks the --help of every kinemo command (kinemo, and through it
kinemo-vision for `cube`/`demo` and kinemo-bench for `bench`) and checks:
  - `kinemo --help` groups the commands: animate and the studio first, then
    characters, cube and robot, services and stores, evaluation and
    benchmarks; no command left out of the groups;
  - one spelling per concept: no command shows `--output`; every `--out` is
    also `-o`; every row of docs/cli.md's table "One spelling per concept":
    each command in "used by" (or one of its subcommands) shows one of the
    row's spellings, no command shows a deprecated spelling of the row, and
    each deprecated spelling still parses, with a note on stderr;
  - the help a newcomer reads: `animate --help` says in one line each what
    gc, gmg and bodyspeech are and which is the default and why, which
    formats -o writes and which recordings it reads; `audio --help` lists
    the formats that work, MP3 included.

  help_spellings_test.py BUILD_DIR SOURCE_DIR
"""
import os
import re
import subprocess
import sys

build, src = sys.argv[1], sys.argv[2]
KINEMO = os.path.join(build, "services/cli/kinemo")
env = dict(os.environ, KINEMO_STORE_DIR=os.path.join(build, "help-test-store"))
failures = []


def fail(msg):
    failures.append(msg)
    print("FAIL:", msg, file=sys.stderr)


def run(args, timeout=60):
    p = subprocess.run([KINEMO] + args, capture_output=True, text=True, timeout=timeout, env=env)
    return p.returncode, p.stdout, p.stderr


GROUPS = ["Animate speech (start here)", "Characters", "Cube and robot", "Services and stores",
          "Evaluation and benchmarks"]
SUBCOMMAND_SECTIONS = set(GROUPS + ["Subcommands", "Other"])


def parse_help(text):
    """(option name sets, subcommand names, section titles) of a --help."""
    options, subcommands, sections = [], [], []
    section = None
    for line in text.splitlines():
        if not line.strip():
            section = None if section != "Options" else section
            continue
        if not line.startswith(" ") and line.rstrip().endswith(":"):
            section = line.rstrip()[:-1]
            sections.append(section)
            continue
        if line.startswith("[Option Group"):
            section = "Options"
            continue
        stripped = line.strip()
        if stripped.startswith("-"):
            names = stripped.split()[0]
            options.append(set(n for n in names.split(",") if n.startswith("-")))
        elif section in SUBCOMMAND_SECTIONS and line.startswith("  ") and not line.startswith("   "):
            subcommands.append(stripped.split()[0])
    return options, subcommands, sections


# ---- Walk every command.
helps = {}  # "animate" / "crf train" -> (options, subcommands, text)


def walk(path):
    rc, out, err = run(path + ["--help"])
    if rc != 0:
        fail(f"kinemo {' '.join(path)} --help exited {rc}: {err.strip()}")
        return
    options, subs, sections = parse_help(out)
    helps[" ".join(path)] = (options, subs, out)
    for s in subs:
        walk(path + [s])


rc, root, err = run(["--help"])
assert rc == 0, err
_, top, sections = parse_help(root)
want = GROUPS
groups = [s for s in sections if s not in ("Options",)]
if groups != want:
    fail(f"kinemo --help groups {groups}, want {want}")
first = root.split("Animate speech (start here):")[1].split("\n\n")[0] if "Animate speech" in root else ""
if not re.search(r"^\s+animate\s", first, re.M) or not re.search(r"^\s+studio\s", first, re.M):
    fail("kinemo --help: animate and studio are not the first group")
if "\nOther:" in root:
    fail("kinemo --help: commands outside the groups (Other)")
for cmd in top:
    walk([cmd])
print(f"{len(helps)} commands' --help read")
for must in ("animate", "retarget", "cube render", "demo vleo", "bench long", "bvh convert", "crf train"):
    if must not in helps:
        fail(f"kinemo {must} --help was not reached")


def names_of(cmd):
    return set().union(*helps[cmd][0]) if helps[cmd][0] else set()


# ---- One spelling per concept, everywhere.
for cmd, (options, _, _) in helps.items():
    for names in options:
        if "--output" in names:
            fail(f"kinemo {cmd} --help shows --output (the spelling is -o/--out)")
        if "--out" in names and "-o" not in names:
            fail(f"kinemo {cmd}: --out without -o")

cli_page = open(os.path.join(src, "docs/cli.md"), encoding="utf-8").read()
table = cli_page.split("## One spelling per concept")[1].split("\n\n")[2]
rows = [l for l in table.splitlines() if l.startswith("| ") and not l.startswith("| concept") and "---" not in l]
assert len(rows) >= 8, table


def commands_in(cell):
    """`crf train`, `session *`, `kinemo-health` -> command paths."""
    out = []
    for c in re.findall(r"`([^`]+)`", cell):
        c = c.strip()
        if c.startswith("kinemo-health") or c.startswith("-"):
            continue  # its own binary (tests/integration/deploy checks it); an option, not a command
        if c.endswith(" *"):
            base = c[:-2]
            out += [k for k in helps if k.startswith(base + " ")]
        elif "/" in c:  # `cube push/ls/rm`
            words = c.split()
            out += [" ".join(words[:-1] + [w]) for w in words[-1].split("/")]
        else:
            out.append(c)
    return out


def spellings_in(cell):
    return set(re.findall(r"(?<![\w-])(--?[a-z][a-z0-9-]*)", " ".join(re.findall(r"`([^`]+)`", cell))))


checked = 0
for row in rows:
    cells = [c.strip() for c in row.strip().strip("|").split("|")]
    concept, spelling, used_by, deprecated = cells[0], cells[1], cells[2], cells[3] if len(cells) > 3 else ""
    wanted = spellings_in(spelling)
    for cmd in commands_in(used_by):
        family = [k for k in helps if k == cmd or k.startswith(cmd + " ")]
        if not family:
            fail(f"docs/cli.md table ({concept}): no command `{cmd}`")
            continue
        if not any(names_of(k) & wanted for k in family):
            fail(f"docs/cli.md table ({concept}): kinemo {cmd} shows none of {sorted(wanted)}")
        checked += 1
    for old in re.findall(r"`([^`]+)`", deprecated):
        parts = old.split()
        if parts[0] == "kinemo-health":
            continue
        # `bvh convert IN OUT`: a positional; the others: CMD[/CMD2] --opt[/--opt2].
        if parts[-1] == "OUT":
            invocations = [parts[:-2] + [os.path.join(src, "tests/data/motion/dataset-1_bye_normal_001.bvh"),
                                         os.path.join(build, "help-test-old.bvh")]]
        else:
            invocations = []
            last_cmd = parts[-2].split("/")
            for sub in last_cmd:
                cmd = " ".join(parts[:-2] + [sub])
                for opt in parts[-1].split("/"):
                    if cmd not in helps:
                        fail(f"docs/cli.md table ({concept}): deprecated `{old}`: no command `{cmd}`")
                        continue
                    if opt in names_of(cmd):
                        fail(f"kinemo {cmd} --help shows the deprecated {opt}")
                    value = [] if opt.startswith("--all") else ["1"]
                    invocations.append(cmd.split() + [opt] + value + ["--help"])
        for args in invocations:
            rc, out, err = run(args)
            if "is deprecated" not in err or "not expected" in err:
                fail(f"`kinemo {' '.join(args)}`: no deprecation note, or refused: {err.strip()[:300]}")
            checked += 1
print(f"{checked} table entries checked")

# ---- Help for a newcomer.
animate = helps.get("animate", ([], [], ""))[2]
for method in ("gc", "gmg", "bodyspeech"):
    if not re.search(rf"^\s+{method}\s+\S", animate, re.M):
        fail(f"animate --help: no line saying what {method} is")
if not re.search(r"bodyspeech.*default|default.*bodyspeech", animate, re.S | re.I) or "needs no trained model" not in animate:
    fail("animate --help: the default method and why are not said")
out_line = next((l for l in animate.splitlines() if "-o,--out" in l), "")
if ".bvh" not in out_line.lower() or ".glb" not in out_line.lower():
    fail(f"animate --help: -o does not say it writes BVH, and GLB with --rig: {out_line}")
if "MP3" not in animate:
    fail("animate --help: the recording formats (MP3 included) are not listed")
for cmd in ("audio", "audio info"):
    text = helps.get(cmd, ([], [], ""))[2]
    if "MP3" not in text:
        fail(f"{cmd} --help: MP3 is not listed")

if failures:
    print(f"{len(failures)} failure(s)", file=sys.stderr)
    sys.exit(1)
print("PASS")
