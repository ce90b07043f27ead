"""A model's 'connections:' section: 'producer.port -> consumer.port', with ports found
by their names or deprecated aliases."""

from __future__ import annotations

import re

from ..dataflow import Endpoint
from ..errors import Pos, Reporter, did_you_mean
from ..loader import Document
from .decls import MAX_CONNECTIONS, Connection, Instance

CONNECTION_RE = re.compile(r"^\s*([^\s.]+)\.([^\s.]+)\s*->\s*([^\s.]+)\.([^\s.]+)\s*$")


def _parse_connection(doc, rep, path, text, comps, components,
                      renamed: dict | None = None) -> Connection | None:
    pos = doc.pos(*path)
    if isinstance(text, dict) and set(text) == {"from", "to"}:
        text = f"{text['from']} -> {text['to']}"
    if not isinstance(text, str):
        rep.error(pos, "a connection is written 'producer.port -> consumer.port'")
        return None
    m = CONNECTION_RE.match(text)
    if not m:
        rep.error(pos, f"cannot read connection {text!r}",
                  "write it as 'producer.port -> consumer.port'")
        return None
    src, dst = Endpoint(m[1], m[2]), Endpoint(m[3], m[4])
    ok = True
    for written, want in ((src, "out"), (dst, "in")):
        end = written
        if end.component not in components:
            if end.component not in comps:  # else: already reported where it was declared
                rep.error(pos, f"unknown component '{end.component}' in connection",
                          did_you_mean(end.component, comps))
            ok = False
            continue
        ctype = components[end.component].type
        canonical = ctype.canonical_port(end.port)
        if canonical is not None and canonical != end.port:  # a deprecated name
            if renamed is not None:
                renamed.setdefault(end.component, (pos, {}))[1][end.port] = canonical
            end = Endpoint(end.component, canonical)
            if want == "out":
                src = end
            else:
                dst = end
        port = ctype.port(end.port)
        if port is None:
            rep.error(pos, f"'{end.component}' ({ctype.name}) has no port '{end.port}'",
                      did_you_mean(f"{end.component}.{end.port}",
                                   [f"{end.component}.{p}" for p in
                                    (ctype.outputs if want == "out" else ctype.inputs)]))
            ok = False
        elif port.direction != want:
            if want == "out":
                rep.error(pos, f"connection from '{end}', which is an input",
                          "a connection goes from an output to an input: "
                          "'producer.out -> consumer.in'")
            else:
                rep.error(pos, f"connection to '{end}', which is an output",
                          "a connection goes from an output to an input: "
                          "'producer.out -> consumer.in'")
            ok = False
    return Connection(src, dst, pos) if ok else None


def load_connections(doc: Document, rep: Reporter, root: dict, comps: dict,
                     components: dict[str, Instance],
                     renamed: dict[str, tuple[Pos, dict[str, str]]]) -> list[Connection]:
    """The model's 'connections:' (comps: its 'components:' as written; renamed: filled
    with the deprecated port names each component is connected by)."""
    connections = []
    conns = root.get("connections") or []
    if not isinstance(conns, list):
        rep.error(doc.pos("connections"), "connections must be a list of "
                  "'producer.port -> consumer.port'")
        conns = []
    elif len(conns) > MAX_CONNECTIONS:
        rep.error(doc.key_pos("connections"),
                  f"the system has {len(conns):,} connections; at most {MAX_CONNECTIONS:,} "
                  "are allowed", "split it into several systems")
        rep.raise_if_errors()
    for i, text in enumerate(conns):
        conn = _parse_connection(doc, rep, ("connections", i), text, comps, components,
                                 renamed)
        if conn is not None:
            connections.append(conn)
    return connections
