#!/usr/bin/env python3
"""Check every relative link (file and #anchor) in README.md and docs/**/*.md,
and every citation of a doc section in the sources (common/, services/,
bench/, proto/, cmake/, CMakeLists.txt): `docs/x.md "Section"` or
`README "Section"` in a comment must name a page that exists and a heading of
it that starts with that text (or a bold paragraph label, **Section**).

Usage: python3 tests/tools/check_doc_links.py [REPO_ROOT]  (exit 1 and one line
per broken link). Anchors are GitHub's heading slugs. ctest: docs_links (unit)."""
import os, re, sys, glob, unicodedata
root = sys.argv[1] if len(sys.argv) > 1 else '.'
os.chdir(root)
files = ['README.md'] + sorted(glob.glob('docs/**/*.md', recursive=True))

def slug(h):
    # GitHub: lower-case, drop punctuation except - and _, spaces -> -
    h = re.sub(r'<[^>]+>', '', h).strip().lower()
    out = []
    for ch in h:
        cat = unicodedata.category(ch)
        if ch in '-_' or ch == ' ' or cat[0] in 'LN':
            out.append('-' if ch == ' ' else ch)
    return ''.join(out)

def labels(path):
    """(kind, text) per heading ('h', without markup) and bold paragraph
    label ('b', **text** at a line's start) of a page, code blocks skipped."""
    inblock = False
    for line in open(path, encoding='utf-8'):
        if line.startswith('```'):
            inblock = not inblock
            continue
        if inblock: continue
        m = re.match(r'^(#{1,6})\s+(.*?)\s*#*\s*$', line)
        if m:
            text = re.sub(r'`', '', m.group(2))
            yield 'h', re.sub(r'\[([^\]]*)\]\([^)]*\)', r'\1', text)
        for b in re.findall(r'^\*\*([^*]+)\*\*', line):
            yield 'b', b

def anchors(path):
    a, seen = set(), {}
    for kind, text in labels(path):
        if kind != 'h': continue
        s = slug(text)
        n = seen.get(s, 0); seen[s] = n + 1
        a.add(s if n == 0 else f'{s}-{n}')
    return a

bad = 0; count = 0
for f in files:
    txt = open(f, encoding='utf-8').read()
    txt = re.sub(r'```.*?```', '', txt, flags=re.S)
    txt = re.sub(r'`[^`\n]*`', '', txt)
    for m in re.finditer(r'!?\[[^\]]*\]\(([^)\s]+)\)', txt):
        url = m.group(1)
        if re.match(r'^[a-z]+:', url): continue
        count += 1
        path, _, frag = url.partition('#')
        target = os.path.normpath(os.path.join(os.path.dirname(f), path)) if path else f
        if not os.path.exists(target):
            print(f'{f}: missing file {url}'); bad += 1; continue
        if frag and target.endswith('.md'):
            if frag not in anchors(target):
                print(f'{f}: missing anchor {url}'); bad += 1


cited = 0
sources = ['CMakeLists.txt']
for top in ['common', 'services', 'bench', 'proto', 'cmake']:
    for dirpath, _, names in os.walk(top):
        sources += [os.path.join(dirpath, n) for n in sorted(names)
                    if n.endswith(('.h', '.cc', '.proto', '.cmake', '.txt', '.py', '.sh', '.textproto'))]
for f in sorted(sources):
    try:
        txt = open(f, encoding='utf-8').read()
    except (UnicodeDecodeError, OSError):
        continue
    # A citation may run over comment lines: join them.
    flat = re.sub(r'\n[ \t]*(//+|#+)[ \t]*', ' ', txt)
    for m in re.finditer(r'\b(README(?:\.md)?|docs/[\w/.-]+?\.md)(?:#[\w-]+)?,? "([^"\n]{1,80})"', flat):
        doc, head = m.group(1), m.group(2)
        path = 'README.md' if doc.startswith('README') else doc
        cited += 1
        if not os.path.exists(path):
            print(f'{f}: cites missing {doc}'); bad += 1
        elif not any(h.lower().startswith(head.lower()) for _, h in labels(path)):
            print(f'{f}: cites {doc} "{head}", which has no such section'); bad += 1

print(f'{count} relative links and {cited} section citations in the sources checked, {bad} broken')
sys.exit(1 if bad else 0)
