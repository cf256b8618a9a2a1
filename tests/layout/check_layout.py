#!/usr/bin/env python3
"""Checks the shape docs/architecture.md promises, on the source tree itself.

1. lib mirrors its API: every public header lib/include/gmr/X/Y.h has its
   implementation lib/src/X/Y.cpp (header-only declarations are not allowed
   to hide elsewhere).
2. No include loops between lib folders: the graph "folder A includes a
   header of folder B" (public gmr/B/... or private B/... from lib/src) over
   lib/include/gmr and lib/src is acyclic.
3. The client's public headers include no generated protobuf header.
4. The server's folders depend one way (docs/architecture.md, "The server
   in rooms"): a file of server/src includes server headers only of its own
   layer or those below, in the order transport < streams < live < the
   top-level owners (catalog, admission) < requests < http < the
   composition root (server.cpp, server_impl.h); server_impl.h is included
   by server/src/server.cpp alone, anywhere in the repository.
5. No server/src file is over 400 lines.

Usage: check_layout.py REPO_ROOT. Prints what it checked and every
violation; exits 1 when there is one. check_layout.py --self-test builds a
small tree that breaks each promise and checks that each break is reported.
"""
import pathlib
import re
import sys

INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.M)

# The server's layers, lowest first (rule 4).
SERVER_LAYERS = ["transport", "streams", "live", "owners", "requests", "http", "root"]
SERVER_ROOT_FILES = {"server.cpp", "server_impl.h"}
SERVER_MAX_LINES = 400


def server_layer(rel):
    """The layer of a server/src file, from its path relative to server/src."""
    if len(rel.parts) > 1:
        return rel.parts[0]
    return "root" if rel.name in SERVER_ROOT_FILES else "owners"


def check_server(root, problems):
    """Rules 4 and 5 on server/src; the summary lines."""
    src = root / "server" / "src"
    files = sorted(src.rglob("*.h")) + sorted(src.rglob("*.cpp"))
    edges = set()
    for f in files:
        rel = f.relative_to(src)
        here = server_layer(rel)
        if here not in SERVER_LAYERS:
            problems.append(f"server/src/{rel}: in no layer ({', '.join(SERVER_LAYERS[:-2])}, or the top level)")
            continue
        text = f.read_text()
        for target in INCLUDE.findall(text):
            if not (src / target).is_file():
                continue
            there = server_layer(pathlib.Path(target))
            if there == "root" and rel.as_posix() != "server.cpp" and target != rel.as_posix():
                problems.append(f"server/src/{rel} includes {target}: only server.cpp includes the composition root")
            elif there in SERVER_LAYERS and SERVER_LAYERS.index(there) > SERVER_LAYERS.index(here):
                problems.append(f"server/src/{rel} ({here}) includes {target} ({there}): a lower layer includes a higher one")
            elif there != here:
                edges.add((here, there))
        lines = text.count("\n")
        if lines > SERVER_MAX_LINES:
            problems.append(f"server/src/{rel}: {lines} lines, over {SERVER_MAX_LINES}")
    # Nobody but server.cpp includes the root, in tests, fuzzing or benchmarks either.
    for folder in ("tests", "fuzz", "bench", "client"):
        for f in sorted((root / folder).rglob("*")):
            if f.suffix not in (".h", ".cpp") or "node_modules" in f.parts:
                continue
            if any(t.endswith("server_impl.h") for t in INCLUDE.findall(f.read_text(errors="replace"))):
                problems.append(f"{f.relative_to(root)} includes server_impl.h: only server.cpp includes the composition root")
    summary = [f"checked {len(files)} server files in {len(SERVER_LAYERS)} layers "
               f"({' < '.join(SERVER_LAYERS)}), none over {SERVER_MAX_LINES} lines"]
    for layer in SERVER_LAYERS:
        below = sorted({there for here, there in edges if here == layer}, key=SERVER_LAYERS.index)
        summary.append(f"  server {layer} -> {', '.join(below) or '(nothing)'}")
    return summary


def lib_folder(path, lib):
    """The lib folder (core, ops, ...) a lib file belongs to."""
    rel = path.relative_to(lib)
    if rel.parts[0] == "include":
        return rel.parts[2]  # include/gmr/<folder>/...
    return rel.parts[1]  # src/<folder>/...


def included_folder(target, lib, own_dir):
    """The lib folder an #include "target" names, or None (not lib)."""
    parts = target.split("/")
    if parts[0] == "gmr" and len(parts) >= 3 and (lib / "include" / target).is_file():
        return parts[1]
    if len(parts) >= 2 and (lib / "src" / target).is_file():
        return parts[0]
    if len(parts) == 1 and (own_dir / target).is_file():
        return None  # same folder
    return None


def find_cycle(graph):
    """A list of folders forming a cycle, or None."""
    state = {}
    stack = []

    def visit(node):
        state[node] = 1
        stack.append(node)
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                return stack[stack.index(nxt):] + [nxt]
            if nxt not in state:
                found = visit(nxt)
                if found:
                    return found
        stack.pop()
        state[node] = 2
        return None

    for node in sorted(graph):
        if node not in state:
            found = visit(node)
            if found:
                return found
    return None


def check(root):
    """The violations in the tree at `root`, and a summary of what was read."""
    lib = root / "lib"
    problems = []

    headers = sorted((lib / "include" / "gmr").rglob("*.h"))
    for h in headers:
        rel = h.relative_to(lib / "include" / "gmr")
        impl = lib / "src" / rel.with_suffix(".cpp")
        if not impl.is_file():
            problems.append(f"lib/include/gmr/{rel}: no implementation at lib/src/{rel.with_suffix('.cpp')}")

    graph = {}
    files = headers + sorted((lib / "src").rglob("*.h")) + sorted((lib / "src").rglob("*.cpp"))
    for f in files:
        here = lib_folder(f, lib)
        graph.setdefault(here, set())
        for target in INCLUDE.findall(f.read_text()):
            there = included_folder(target, lib, f.parent)
            if there and there != here:
                graph[here].add(there)
    cycle = find_cycle(graph)
    if cycle:
        problems.append("include loop between lib folders: " + " -> ".join(cycle))

    # Followed through every header of ours it reaches (lib, wire, client).
    client_headers = sorted((root / "client" / "include").rglob("*.h"))
    include_roots = [root / "client" / "include", root / "proto" / "wire" / "include", lib / "include"]
    for h in client_headers:
        seen, todo = set(), [h]
        while todo:
            f = todo.pop()
            if f in seen:
                continue
            seen.add(f)
            for target in INCLUDE.findall(f.read_text()):
                if target.endswith(".pb.h"):
                    via = "" if f == h else f" (through {f.relative_to(root)})"
                    problems.append(f"{h.relative_to(root)} includes the generated {target}{via}")
                todo += [r / target for r in include_roots if (r / target).is_file()]

    if len(headers) == 0 or len(client_headers) == 0:
        problems.append("found no headers: is REPO_ROOT right?")
    summary = [f"checked {len(headers)} public lib headers, {len(files)} lib files in {len(graph)} folders, "
               f"{len(client_headers)} client headers"]
    summary += [f"  {folder} -> {', '.join(sorted(graph[folder])) or '(nothing)'}" for folder in sorted(graph)]
    if (root / "server" / "src").is_dir():
        summary += check_server(root, problems)
    return problems, summary


def self_test():
    """Each broken promise in a made-up tree is reported; the mended tree passes."""
    import tempfile

    with tempfile.TemporaryDirectory() as tmp:
        root = pathlib.Path(tmp)

        def write(rel, text):
            path = root / rel
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(text)

        write("lib/include/gmr/a/x.h", '#pragma once\n#include "gmr/b/y.h"\n')
        write("lib/src/a/x.cpp", '#include "gmr/a/x.h"\n')
        write("lib/include/gmr/b/y.h", "#pragma once\n")  # no lib/src/b/y.cpp
        write("lib/src/b/helper.cpp", '#include "gmr/a/x.h"\n')  # b -> a while a -> b
        write("client/include/gmr/client/c.h", '#include "gmr/wire/w.h"\n')
        write("proto/wire/include/gmr/wire/w.h", '#include "gmr/stream/v1/stream.pb.h"\n')
        write("server/src/transport/t.h", '#pragma once\n#include "requests/r.h"\n')  # upward
        write("server/src/requests/r.h", '#pragma once\n#include "transport/t.h"\n')
        write("server/src/server_impl.h", '#pragma once\n#include "requests/r.h"\n')
        write("server/src/server.cpp", '#include "server_impl.h"\n')
        write("server/src/http/h.cpp", '#include "server_impl.h"\n')  # the root, outside server.cpp
        write("tests/t.cpp", '#include "server_impl.h"\n')
        write("server/src/streams/long.cpp", "//\n" * 401)
        problems, _ = check(root)
        expected = ["lib/include/gmr/b/y.h: no implementation", "include loop between lib folders: a -> b -> a",
                    "includes the generated gmr/stream/v1/stream.pb.h (through proto/wire/include/gmr/wire/w.h)",
                    "server/src/transport/t.h (transport) includes requests/r.h (requests): a lower layer",
                    "server/src/http/h.cpp includes server_impl.h: only server.cpp",
                    "tests/t.cpp includes server_impl.h", "server/src/streams/long.cpp: 401 lines, over 400"]
        missing = [e for e in expected if not any(e in p for p in problems)]
        for e in missing:
            print(f"SELF-TEST: not reported: {e}")
        write("lib/src/b/y.cpp", '#include "gmr/b/y.h"\n')
        (root / "lib/src/b/helper.cpp").unlink()
        write("client/include/gmr/client/c.h", "#pragma once\n")
        write("server/src/transport/t.h", "#pragma once\n")
        (root / "server/src/http/h.cpp").unlink()
        (root / "tests/t.cpp").unlink()
        write("server/src/streams/long.cpp", "//\n" * 400)
        mended, _ = check(root)
        for p in mended:
            print(f"SELF-TEST: reported in a correct tree: {p}")
        print(f"self-test: {len(expected) - len(missing)} of {len(expected)} breaks reported, "
              f"{len(mended)} false reports")
        return 1 if missing or mended else 0


def main():
    if sys.argv[1:] == ["--self-test"]:
        return self_test()
    problems, summary = check(pathlib.Path(sys.argv[1]).resolve())
    print("\n".join(summary))
    for p in problems:
        print("LAYOUT: " + p)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
