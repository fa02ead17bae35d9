#!/usr/bin/env python3
"""The module graph of a crate, and its import circles.

    python3 .ci/module_graph.py acquire/src [edges|top] [--facade]

Nodes are module files; an edge A -> B when A's non-test code names a path into module B
(`use crate::..`, `super::..`, `self::..`, a child module's name, or a module imported by name;
comments and `#[cfg(test)] mod tests` are left out). With --facade, `pub use` re-exports (a
module's facade) are not edges. `edges` prints every edge, `top` the graph of top-level
modules. Prints each circle (strongly connected component of more than one module) and exits
with 1 when there is one.
"""
import os, re, sys
root = sys.argv[1]  # e.g. acquire/src
FACADE = '--facade' in sys.argv
sys.argv = [a for a in sys.argv if a != '--facade']
mods = {}  # module path tuple -> file
for dp, dn, fn in os.walk(root):
    for f in fn:
        if not f.endswith('.rs'): continue
        p = os.path.join(dp, f); rel = os.path.relpath(p, root)
        if rel.startswith('bin/'): continue
        parts = rel[:-3].split('/')
        if parts[-1] in ('mod', 'lib'): parts = parts[:-1]
        mods[tuple(parts)] = p
def strip(src):
    # cut test modules
    src = re.split(r'#\[cfg\(test\)\]\s*(?:pub\s+)?mod\s+tests\s*\{', src)[0]
    src = re.sub(r'//[^\n]*', '', src)
    return src
def resolve(cur, path):
    # path: list of segments after crate/super/self resolution -> longest module prefix
    for n in range(len(path), 0, -1):
        if tuple(path[:n]) in mods: return tuple(path[:n])
    return None
def expand_use(tree):
    # expand "a::{b, c::{d}}" into list of paths
    tree = tree.strip()
    m = re.match(r'^([\w:]*?)::\{(.*)\}$', tree, re.S)
    if m:
        pre = m.group(1); inner = m.group(2); out = []; depth = 0; cur = ''
        for ch in inner:
            if ch == '{': depth += 1
            if ch == '}': depth -= 1
            if ch == ',' and depth == 0:
                if cur.strip(): out += [pre + '::' + x for x in expand_use(cur)]
                cur = ''
            else: cur += ch
        if cur.strip(): out += [pre + '::' + x for x in expand_use(cur)]
        return out
    return [re.split(r'\s+as\s+', tree)[0]]
edges = {}
for mod, p in mods.items():
    src = strip(open(p).read())
    is_dir = os.path.basename(p) in ('mod.rs', 'lib.rs')
    paths = []
    children = {m[-1] for m in mods if len(m) == len(mod) + 1 and m[:len(mod)] == mod} if is_dir else set()
    aliases = {}
    for m in re.finditer(r'(\bpub(?:\([\w:]+\))?\s+)?\buse\s+([^;]*);', src):
        if m.group(1) and FACADE: continue  # a re-export is the module's facade, not a use
        for u in expand_use(m.group(2)):
            first = u.split('::')[0]
            if first in ('crate', 'super', 'self'):
                paths.append(u)
            elif first in children:
                paths.append('self::' + u)
            # a module brought into scope by name: `use crate::session::{self}` / `use super::frame`
            segs = u.split('::')
            if segs[-1] == 'self': segs = segs[:-1]
            if segs and segs[0] in ('crate', 'super', 'self') or (segs and segs[0] in children):
                aliases[segs[-1]] = segs if segs[0] in ('crate', 'super', 'self') else ['self'] + segs
    for m in re.finditer(r'(?<![\w:])((?:crate|super)(?:::\w+)+)', src):
        paths.append(m.group(1))
    # in-body paths whose first segment is a child module or an imported module name
    body = re.sub(r'\buse\s+[^;]*;', '', src)
    for m in re.finditer(r'(?<![\w:])(\w+)((?:::\w+)+)', body):
        first = m.group(1)
        if first in children:
            paths.append('self::' + first + m.group(2))
        elif first in aliases and first not in ('crate', 'super', 'self'):
            paths.append('::'.join(aliases[first]) + m.group(2))
    for path in paths:
        segs = [s for s in path.split('::') if s]
        base = list(mod) if is_dir else list(mod[:-1])
        if segs[0] == 'crate': full = segs[1:]
        elif segs[0] == 'self': full = list(mod) + segs[1:]
        else:
            # super relative to the module
            cur = list(mod)
            while segs and segs[0] == 'super': cur = cur[:-1]; segs = segs[1:]
            full = cur + segs
        if full and full[-1] == 'self': full = full[:-1]
        t = resolve(mod, full)
        if t is not None and t != mod and not (t == tuple(mod[:len(t)])):
            # ignore edges to an ancestor's mod.rs? no: keep them; parent mod.rs is real code
            pass
        if t is not None and t != mod:
            edges.setdefault(mod, set()).add(t)
name = lambda m: '::'.join(m) or 'lib'
# parent -> child declarations (mod x;) are not dependencies; only path uses counted.
# Tarjan SCC
idx = {}; low = {}; st = []; on = set(); sccs = []; c = [0]
sys.setrecursionlimit(10000)
def sc(v):
    idx[v] = low[v] = c[0]; c[0] += 1; st.append(v); on.add(v)
    for w in edges.get(v, ()):
        if w not in idx: sc(w); low[v] = min(low[v], low[w])
        elif w in on: low[v] = min(low[v], idx[w])
    if low[v] == idx[v]:
        comp = []
        while True:
            w = st.pop(); on.discard(w); comp.append(w)
            if w == v: break
        sccs.append(comp)
for v in mods:
    if v not in idx: sc(v)
mode = sys.argv[2] if len(sys.argv) > 2 else 'cycles'
if mode == 'edges':
    for a in sorted(edges):
        print(f"{name(a)} -> {', '.join(sorted(name(b) for b in edges[a]))}")
cyc = [s for s in sccs if len(s) > 1]
print(f"{len(mods)} modules, {sum(len(e) for e in edges.values())} edges, {len(cyc)} cycle(s)")
for s in cyc:
    print(f"cycle of {len(s)}: " + ', '.join(sorted(name(m) for m in s)))
    for a in sorted(s):
        inn = sorted(name(b) for b in edges.get(a, ()) if b in s)
        print(f"   {name(a)} -> {', '.join(inn)}")
if mode == 'top':
    top = {}
    for a, bs in edges.items():
        for b in bs:
            if a[:1] != b[:1] and a and b: top.setdefault(a[0], set()).add(b[0])
    for a in sorted(top): print(f"  {a} -> {', '.join(sorted(top[a]))}")
    # cycles
    idx.clear(); low.clear(); st.clear(); on.clear(); sccs.clear(); c[0]=0
    edges.clear(); edges.update({(a,):{(b,) for b in bs} for a, bs in top.items()})
    for v in list(edges):
        if v not in idx: sc(v)
    for s in sccs:
        if len(s) > 1: print("top-level cycle:", ', '.join(sorted(name(m) for m in s)))
sys.exit(1 if cyc else 0)
