#!/usr/bin/env python3
"""House rules for the Rust sources under src/.

Checks, with nothing but the standard library (no cargo, no rustc):

1. File size: no .rs file under src/ is over 600 lines, its unit tests
   included.  Only unit-test files are exempt: files named tests.rs, living
   in a tests/ folder under src/, or declared as a test-only module
   (`#[cfg(test)] mod chi2;`).
2. Function size: no function is over 150 lines, measured from the line of
   `fn name` to the line of the brace that closes its body.  Braces are
   matched on a copy of the source with comments (line, nested block),
   string literals (plain, raw r#"..."#, byte, C) and char literals masked
   out; lifetimes such as 'a are told apart from chars such as '{'.  Test
   code is exempt: functions inside a `#[cfg(test)] mod` (inline, or a file
   module declared `#[cfg(test)] mod x;`), inside `mod tests { }`, with a
   `#[test]` or `#[cfg(test)]` attribute, or in a unit-test file (rule 1).
3. Import cycles: a file -> file graph is built from the paths the code
   names: `use` trees (grouped, nested, multi-line), `crate::a::b::Item`
   anywhere in code, `super::`/`self::` paths resolved against the module
   the code sits in (inline modules included), 2018-style paths through a
   module's own child modules (`use camera::Camera` in render/mod.rs), and
   `sky::` in the binary crate (src/main.rs and src/cli/).  A path resolves
   to the file of the deepest module it names (the module tree is read from
   `mod x;` declarations starting at src/lib.rs and src/main.rs).  Code in
   test modules and test-only items is ignored.  Strongly connected
   components (Tarjan) with files from more than one folder are failures;
   same-folder ones are only listed with --verbose.  The folder of
   src/a/mod.rs is src/a, that of src/a.rs is src.
4. Layering: the four greps of the house rules, done here as substring
   searches (folders that do not exist are skipped):
       grep -rn "crate::lut" src/render src/mie
       grep -rn "crate::bake" src/lut
       grep -rn "crate::session" src/farm
       grep -rln clap src | grep -v ^src/cli

Why: big files and functions hide structure and make review slow; a cycle
between folders means those folders are not layers but one tangle; and the
greps pin the layering down: render and mie sit below lut, lut below bake,
farm below session, and only the CLI knows about clap.

Usage: scripts/house_check.py [--verbose]
  default    print the violations and a summary; exit 1 if any, else 0
  --verbose  also print the 10 largest files, the 10 longest functions and
             every import cycle, same-folder ones included
"""

import argparse
import os
import re
import sys
from collections import defaultdict

MAX_FILE_LINES = 600
MAX_FN_LINES = 150

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
SRC = "src"

# ---------------------------------------------------------------- lexing

_CAND = re.compile(r'//|/\*|"|\'|\b(?:br|cr|r)#*"')
_RAW = re.compile(r'(?:br|cr|r)(#*)"')
_CHAR = re.compile(r"'(?:\\(?:x[0-9a-fA-F]{2}|u\{[0-9a-fA-F_]*\}|.)|[^\\'\n])'")
_STR_END = re.compile(r'\\.|"', re.S)
_BLOCK = re.compile(r'/\*|\*/')


def _blank(s):
    """Spaces for s, keeping its newlines (so line numbers survive)."""
    return re.sub(r'[^\n]', ' ', s)


def mask(text):
    """Return text with comments, strings and char literals blanked out."""
    out = []
    i = 0
    n = len(text)
    while True:
        m = _CAND.search(text, i)
        if not m:
            out.append(text[i:])
            break
        s = m.start()
        out.append(text[i:s])
        tok = m.group()
        if tok == '//':
            e = text.find('\n', s)
            e = n if e < 0 else e
        elif tok == '/*':
            depth = 0
            e = n
            for b in _BLOCK.finditer(text, s):
                depth += 1 if b.group() == '/*' else -1
                if depth == 0:
                    e = b.end()
                    break
        elif tok == '"':
            j = s + 1
            e = n
            for q in _STR_END.finditer(text, j):
                if q.group() == '"':
                    e = q.end()
                    break
        elif tok == "'":
            c = _CHAR.match(text, s)
            if c:
                e = c.end()
            else:  # a lifetime or a label: leave it
                out.append("'")
                i = s + 1
                continue
        else:  # raw string
            r = _RAW.match(text, s)
            close = '"' + r.group(1)
            e = text.find(close, r.end())
            e = n if e < 0 else e + len(close)
        out.append(_blank(text[s:e]))
        i = e
    return ''.join(out)


class Source:
    """One file: raw text, masked text, and line lookup."""

    def __init__(self, rel):
        self.rel = rel
        with open(os.path.join(ROOT, rel), encoding='utf-8', errors='replace') as f:
            self.text = f.read()
        self.lines = self.text.splitlines()
        self.masked = mask(self.text)
        self._starts = [0]
        for m in re.finditer('\n', self.text):
            self._starts.append(m.end())

    def line_of(self, pos):
        lo, hi = 0, len(self._starts) - 1
        while lo < hi:
            mid = (lo + hi + 1) // 2
            if self._starts[mid] <= pos:
                lo = mid
            else:
                hi = mid - 1
        return lo + 1

    def line_text(self, line):
        return self.lines[line - 1].strip() if 0 < line <= len(self.lines) else ''


_BRACES = re.compile(r'[{}]')


def match_brace(masked, open_pos):
    """Position of the } that closes the { at open_pos (or len)."""
    depth = 0
    for m in _BRACES.finditer(masked, open_pos):
        depth += 1 if m.group() == '{' else -1
        if depth == 0:
            return m.start()
    return len(masked)


def item_prefix(masked, pos):
    """The attributes and qualifiers written before the item at pos."""
    k = max(masked.rfind(';', 0, pos), masked.rfind('{', 0, pos), masked.rfind('}', 0, pos))
    return masked[k + 1:pos]


_TEST_ATTR = re.compile(r'#\s*\[\s*(?:cfg\s*\(\s*test\s*\)|(?:\w+\s*::\s*)*test\s*[\]\(])')
_CFG_TEST = re.compile(r'#\s*\[\s*cfg\s*\(\s*test\s*\)\s*\]')


def is_test_file(rel):
    parts = rel.split('/')
    return parts[-1] == 'tests.rs' or 'tests' in parts[1:-1]


# ---------------------------------------------------------------- module tree

_MOD_DECL = re.compile(r'\bmod\s+(r#)?([A-Za-z_]\w*)\s*([;{])')


class Module:
    def __init__(self, path, file, parent, inline_span=None, test=False):
        self.path = path            # tuple of names from the crate root
        self.file = file            # rel path of the file holding it
        self.parent = parent
        self.children = {}
        self.inline_span = inline_span  # (start, end) in file, if inline
        self.test = test            # test-only (cfg(test) or mod tests)


class Crate:
    def __init__(self, name, root_rel, sources):
        self.name = name
        self.root = Module((), root_rel, None)
        self.files = {}             # rel -> file Module
        self.inline = defaultdict(list)  # rel -> inline Modules
        self.missing = []
        self.sources = sources
        self._load(self.root, sources, False)

    def _load(self, mod, sources, test):
        rel = mod.file
        if rel not in sources:
            if not os.path.isfile(os.path.join(ROOT, rel)):
                self.missing.append(rel)
                return
            sources[rel] = Source(rel)
        src = sources[rel]
        self.files[rel] = mod
        if re.match(r'\s*#!\s*\[\s*cfg\s*\(\s*test\s*\)\s*\]', src.masked):
            mod.test = True
        base = os.path.dirname(rel)
        stem = os.path.basename(rel)[:-3]
        if stem not in ('lib', 'main', 'mod'):
            base = os.path.join(base, stem)
        self._scan(mod, src, 0, len(src.masked), base, test or mod.test)

    def _scan(self, mod, src, start, end, base, test):
        m_text = src.masked
        pos = start
        while True:
            m = _MOD_DECL.search(m_text, pos, end)
            if not m:
                return
            name = m.group(2)
            attrs = item_prefix(m_text, m.start())
            child_test = test or bool(_CFG_TEST.search(attrs))
            if m.group(3) == ';':
                sub_base = os.path.join(base, name)
                cand = [sub_base + '.rs', os.path.join(sub_base, 'mod.rs')]
                file = next((c for c in cand if os.path.isfile(os.path.join(ROOT, c))), cand[0])
                child = Module(mod.path + (name,), file, mod, test=child_test)
                mod.children[name] = child
                self._load(child, self.sources, child_test)
                pos = m.end()
            else:
                close = match_brace(m_text, m.end() - 1)
                child_test = child_test or name == 'tests'
                child = Module(mod.path + (name,), mod.file, mod, (m.start(), close + 1), child_test)
                mod.children[name] = child
                self.inline[mod.file].append(child)
                self._scan(child, src, m.end(), close, os.path.join(base, name), child_test)
                pos = close + 1

    def module_at(self, rel, pos):
        """The innermost module containing pos in file rel."""
        best = self.files[rel]
        for im in self.inline.get(rel, ()):
            s, e = im.inline_span
            if s <= pos < e and len(im.path) > len(best.path):
                best = im
        return best

    def resolve(self, segs, start_mod=None):
        """File of the deepest module named by segs from start_mod (root)."""
        mod = start_mod or self.root
        for s in segs:
            if s in mod.children:
                mod = mod.children[s]
            else:
                break
        return mod


src_cache = {}

# ---------------------------------------------------------------- paths

_IDENT = r'(?:r#)?[A-Za-z_]\w*'
_USE = re.compile(r'(?<![\w:])use\b')
_USE_TOK = re.compile(r'::|' + _IDENT + r'|[{},*;]|\S')
_CODE_PATH = re.compile(r'(?<![\w:])\$?(' + _IDENT + r')((?:\s*::\s*' + _IDENT + r')+)')


def parse_use(masked, pos):
    """Parse the use tree after `use` at pos: ([(segments, leaf_pos)], end)."""
    toks = []
    for m in _USE_TOK.finditer(masked, pos + 3):
        toks.append((m.group(), m.start()))
        if m.group() == ';':
            break
    end = toks[-1][1] + 1 if toks else pos + 3
    out = []
    i = 0

    def tree(prefix):
        nonlocal i
        segs = list(prefix)
        last = None
        while i < len(toks):
            t, p = toks[i]
            if t == '{':
                i += 1
                while i < len(toks) and toks[i][0] != '}':
                    tree(segs)
                    if i < len(toks) and toks[i][0] == ',':
                        i += 1
                i += 1
                return
            if t == '*':
                i += 1
                if segs:
                    out.append((segs, p))
                return
            if t == '::':
                i += 1
                continue
            if t in (',', '}', ';'):
                break
            if t == 'as':
                i += 2
                continue
            if re.match(_IDENT, t):
                if t != 'self' or not segs:
                    segs = segs + [t]
                last = p
                i += 1
                continue
            i += 1
        if segs and last is not None:
            out.append((segs, last))

    if toks and toks[0][0] == '::':
        return [], end
    tree([])
    return out, end


class Graph:
    def __init__(self):
        # a -> b -> line -> (source text, [use paths shown when the line alone is unclear])
        self.edges = defaultdict(lambda: defaultdict(dict))

    def add(self, a, b, line, text, path=None):
        if a == b:
            return
        t, paths = self.edges[a][b].setdefault(line, (text, []))
        if path and path not in paths:
            paths.append(path)

    def lines(self, a, b):
        for line, (text, paths) in sorted(self.edges[a][b].items()):
            if paths:
                text += '   [use %s]' % ', '.join(paths)
            yield line, text


def test_spans(crate, rel):
    spans = [im.inline_span for im in crate.inline.get(rel, ()) if im.test]
    src = src_cache[rel]
    m_text = src.masked
    for a in _CFG_TEST.finditer(m_text):
        # a #[cfg(test)] item other than a module: blank the item.
        j = a.end()
        nxt = re.compile(r'[;{]').search(m_text, j)
        if not nxt:
            continue
        if re.search(r'\bmod\b', m_text[j:nxt.start()]):
            continue  # modules are handled through the module tree
        e = match_brace(m_text, nxt.start()) + 1 if nxt.group() == '{' else nxt.end()
        spans.append((a.start(), e))
    return spans


def in_spans(pos, spans):
    return any(s <= pos < e for s, e in spans)


def build_graph(crates, lib):
    g = Graph()
    for crate in crates:
        for rel, fmod in crate.files.items():
            if fmod.test or is_test_file(rel):
                continue
            src = src_cache[rel]
            spans = test_spans(crate, rel)
            m_text = src.masked
            use_spans = []

            def resolve(segs, pos):
                mod = crate.module_at(rel, pos)
                head = segs[0]
                if head.startswith('$'):
                    head = head[1:]
                if head == 'crate':
                    target_crate, start, rest = crate, crate.root, segs[1:]
                elif head == 'sky' and crate is not lib and lib is not None:
                    target_crate, start, rest = lib, lib.root, segs[1:]
                elif head in ('super', 'self'):
                    target_crate, start, rest = crate, mod, segs
                    while rest and rest[0] in ('super', 'self'):
                        if rest[0] == 'super':
                            start = start.parent or start
                        rest = rest[1:]
                elif head in mod.children:
                    target_crate, start, rest = crate, mod, segs
                else:
                    return None
                while rest and rest[0] == 'super':
                    start = start.parent or start
                    rest = rest[1:]
                return target_crate.resolve(rest, start).file

            for u in _USE.finditer(m_text):
                paths, end = parse_use(m_text, u.start())
                use_spans.append((u.start(), end))
                if in_spans(u.start(), spans):
                    continue
                for segs, p in paths:
                    tgt = resolve(segs, p)
                    if tgt:
                        line = src.line_of(p)
                        text = src.line_text(line)
                        # inside a multi-line use: say which path
                        full = None if re.search(r'\buse\b', text) else '::'.join(segs)
                        g.add(rel, tgt, line, text, full)
            for m in _CODE_PATH.finditer(m_text):
                if in_spans(m.start(), spans) or in_spans(m.start(), use_spans):
                    continue
                segs = [m.group(1)] + re.findall(_IDENT, m.group(2))
                tgt = resolve(segs, m.start())
                if tgt:
                    line = src.line_of(m.start())
                    g.add(rel, tgt, line, src.line_text(line))
    return g


def tarjan(nodes, edges):
    index = {}
    low = {}
    on = set()
    stack = []
    sccs = []
    counter = [0]
    sys.setrecursionlimit(10000)

    def visit(v):
        index[v] = low[v] = counter[0]
        counter[0] += 1
        stack.append(v)
        on.add(v)
        for w in sorted(edges.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = []
            while True:
                w = stack.pop()
                on.discard(w)
                comp.append(w)
                if w == v:
                    break
            sccs.append(sorted(comp))

    for v in sorted(nodes):
        if v not in index:
            visit(v)
    return [c for c in sccs if len(c) > 1]


def folder(rel):
    return os.path.dirname(rel)


# ---------------------------------------------------------------- functions

_FN = re.compile(r'\bfn\s+(' + _IDENT + r')')
_SIG_STOP = re.compile(r'[()\[\]{};]')


def functions(src):
    """[(name, line, n_lines, pos)] for every fn with a body."""
    out = []
    m_text = src.masked
    for m in _FN.finditer(m_text):
        depth = 0
        body = None
        for s in _SIG_STOP.finditer(m_text, m.end()):
            c = s.group()
            if c in '([':
                depth += 1
            elif c in ')]':
                depth -= 1
            elif depth == 0:
                body = s.start() if c == '{' else None
                break
        if body is None:
            continue
        close = match_brace(m_text, body)
        first = src.line_of(m.start())
        last = src.line_of(close)
        out.append((m.group(1), first, last - first + 1, m.start()))
    return out


# ---------------------------------------------------------------- greps

def grep(folders, needle):
    hits = []
    for d in folders:
        if not os.path.isdir(os.path.join(ROOT, d)):
            continue
        for dirpath, dirnames, filenames in os.walk(os.path.join(ROOT, d)):
            dirnames.sort()
            for fn in sorted(filenames):
                full = os.path.join(dirpath, fn)
                rel = os.path.relpath(full, ROOT)
                try:
                    with open(full, encoding='utf-8', errors='replace') as f:
                        for i, line in enumerate(f, 1):
                            if needle in line:
                                hits.append((rel, i, line.rstrip('\n')))
                except OSError:
                    pass
    return hits


# ---------------------------------------------------------------- main

def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--verbose', '-v', action='store_true',
                    help='also print the largest files, longest functions and every cycle')
    args = ap.parse_args()

    out = []
    p = out.append
    failures = defaultdict(int)

    # every .rs file under src/
    all_rs = []
    for dirpath, dirnames, filenames in os.walk(os.path.join(ROOT, SRC)):
        dirnames.sort()
        for fn in sorted(filenames):
            if fn.endswith('.rs'):
                all_rs.append(os.path.relpath(os.path.join(dirpath, fn), ROOT))

    crates = []
    lib = None
    if os.path.isfile(os.path.join(ROOT, SRC, 'lib.rs')):
        lib = Crate('lib', SRC + '/lib.rs', src_cache)
        crates.append(lib)
    if os.path.isfile(os.path.join(ROOT, SRC, 'main.rs')):
        crates.append(Crate('bin', SRC + '/main.rs', src_cache))
    for rel in all_rs:
        if rel not in src_cache:
            src_cache[rel] = Source(rel)
    test_module_files = set()
    for c in crates:
        for rel, m in c.files.items():
            if m.test:
                test_module_files.add(rel)
    declared = set()
    for c in crates:
        declared.update(c.files)

    # rule 1
    sizes = sorted(((len(src_cache[r].lines), r) for r in all_rs), reverse=True)
    p('== rule 1: files over %d lines' % MAX_FILE_LINES)
    for n, r in sizes:
        if n > MAX_FILE_LINES and not is_test_file(r) and r not in test_module_files:
            p('%s: %d lines (limit %d)' % (r, n, MAX_FILE_LINES))
            failures['files'] += 1

    # rule 2
    p('== rule 2: functions over %d lines' % MAX_FN_LINES)
    fns = []
    for r in all_rs:
        src = src_cache[r]
        test_file = is_test_file(r) or r in test_module_files
        spans = []
        for c in crates:
            if r in c.files:
                spans += [im.inline_span for im in c.inline.get(r, ()) if im.test]
        # `mod tests {` anywhere counts as test code even if undeclared
        for m in re.finditer(r'\bmod\s+tests\s*\{', src.masked):
            spans.append((m.start(), match_brace(src.masked, m.end() - 1) + 1))
        for name, line, n, pos in functions(src):
            exempt = test_file or in_spans(pos, spans) or bool(_TEST_ATTR.search(item_prefix(src.masked, pos)))
            fns.append((n, r, line, name, exempt))
    for n, r, line, name, exempt in sorted(fns, key=lambda f: (f[1], f[2])):
        if n > MAX_FN_LINES and not exempt:
            p('%s:%d: fn %s is %d lines (limit %d)' % (r, line, name, n, MAX_FN_LINES))
            failures['functions'] += 1

    # rule 3
    g = build_graph(crates, lib)
    nodes = set(g.edges)
    for a in g.edges:
        nodes.update(g.edges[a])
    sccs = tarjan(nodes, g.edges)
    cross = [c for c in sccs if len({folder(f) for f in c}) > 1]
    same = [c for c in sccs if len({folder(f) for f in c}) == 1]

    def print_scc(comp, k, kind):
        p('cycle %d (%s, %d files): %s' % (k, kind, len(comp), ' '.join(comp)))
        members = set(comp)
        for a in comp:
            for b in sorted(g.edges[a]):
                if b in members:
                    mark = '  [cross-folder]' if folder(a) != folder(b) else ''
                    p('  %s -> %s%s' % (a, b, mark))
                    for line, text in g.lines(a, b):
                        p('    %s:%d: %s' % (a, line, text))

    p('== rule 3: import cycles across folders')
    for k, comp in enumerate(cross, 1):
        print_scc(comp, k, 'cross-folder')
        failures['cycles'] += 1

    # rule 4
    p('== rule 4: layering greps')
    greps = [
        ('grep -rn "crate::lut" src/render src/mie', ['src/render', 'src/mie'], 'crate::lut'),
        ('grep -rn "crate::bake" src/lut', ['src/lut'], 'crate::bake'),
        ('grep -rn "crate::session" src/farm', ['src/farm'], 'crate::session'),
    ]
    for label, dirs, needle in greps:
        hits = grep(dirs, needle)
        if hits:
            p('$ ' + label)
            for rel, i, line in hits:
                p('%s:%d:%s' % (rel, i, line))
            failures['greps'] += 1
    clap_files = sorted({h[0] for h in grep([SRC], 'clap')
                         if not (h[0] + '/').startswith(SRC + '/cli/')})
    if clap_files:
        p('$ grep -rln clap src | grep -v ^src/cli')
        for f in clap_files:
            p(f)
        failures['greps'] += 1

    if args.verbose:
        p('== verbose: %d largest files' % 10)
        for n, r in sizes[:10]:
            p('%5d  %s%s' % (n, r, '  (test file, exempt)' if is_test_file(r) else ''))
        p('== verbose: %d longest functions (test code excluded)' % 10)
        for n, r, line, name, exempt in sorted([f for f in fns if not f[4]], key=lambda f: (-f[0], f[1], f[2]))[:10]:
            p('%5d  %s:%d: fn %s' % (n, r, line, name))
        p('== verbose: same-folder import cycles (not failures)')
        for k, comp in enumerate(same, len(cross) + 1):
            print_scc(comp, k, 'same-folder')
        undeclared = [r for r in all_rs if r not in declared]
        if undeclared:
            p('== verbose: .rs files not reached from src/lib.rs or src/main.rs (not in the import graph)')
            for r in undeclared:
                p(r)
        testmods = sorted(test_module_files - {r for r in test_module_files if is_test_file(r)})
        if testmods:
            p('== verbose: test-only file modules (declared under #[cfg(test)]; rule 2 and the graph skip them, rule 1 does not)')
            for r in testmods:
                p(r)

    total = sum(failures.values())
    p('== summary: %d files over %d lines, %d functions over %d lines, '
      '%d cross-folder import cycles (%d same-folder), %d of 4 layering greps failing'
      % (failures['files'], MAX_FILE_LINES, failures['functions'], MAX_FN_LINES,
         failures['cycles'], len(same), failures['greps']))
    p('house_check: %s' % ('FAIL' if total else 'OK'))
    print('\n'.join(out))
    return 1 if total else 0


if __name__ == '__main__':
    sys.exit(main())
