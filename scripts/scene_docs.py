#!/usr/bin/env python3
# SPDX-License-Identifier: GPL-3.0-or-later
"""The table of scene keys in docs/scenes.md, derived from the scene schema.

The scene schema (scene/scene.schema.json, published with the registries' names by `sphles schema`)
is the one declaration of the scene's keys. This script writes its table into docs/scenes.md,
between the markers

    <!-- scene-keys:begin -->
    <!-- scene-keys:end -->

  scripts/scene_docs.py --sphles build/app/sphles docs/scenes.md          # rewrite the table
  scripts/scene_docs.py --sphles build/app/sphles docs/scenes.md --check  # exit 1 if it differs
"""
import argparse
import json
import subprocess
import sys

BEGIN = "<!-- scene-keys:begin -->"
END = "<!-- scene-keys:end -->"


def number_text(value):
    if isinstance(value, float) and value.is_integer() and abs(value) < 1e15:
        value = int(value)
    return str(value)


def bounds_text(node):
    lo_ex, lo_in = node.get("exclusiveMinimum"), node.get("minimum")
    hi_ex, hi_in = node.get("exclusiveMaximum"), node.get("maximum")
    lo = lo_ex if lo_ex is not None else lo_in
    hi = hi_ex if hi_ex is not None else hi_in
    if lo is not None and hi is not None:
        if node.get("type") == "integer" and lo_ex is None and hi_ex is None:
            return f"{number_text(lo)}–{number_text(hi)}"
        return "in {}{}, {}{}".format("(" if lo_ex is not None else "[", number_text(lo),
                                      number_text(hi), ")" if hi_ex is not None else "]")
    if lo is not None:
        return ("> " if lo_ex is not None else "≥ ") + number_text(lo)
    if hi is not None:
        return ("< " if hi_ex is not None else "≤ ") + number_text(hi)
    return ""


def names_text(values):
    return ", ".join(f"`{v}`" for v in values)


def type_text(node):
    kind = node.get("type")
    if isinstance(kind, list):
        kind = " or ".join(kind)
    if "enum" in node:
        return names_text(node["enum"])
    if kind in ("number", "integer"):
        return f"{kind} {bounds_text(node)}".strip()
    if kind == "boolean":
        return "bool"
    if kind == "array":
        items = node.get("items", {})
        text = ("list of " + names_text(items["enum"]) if "enum" in items
                else "list of {}s".format(items.get("type", "value")))
        extra = []
        if node.get("uniqueItems"):
            extra.append("no repeats")
        if node.get("minItems") == 1:
            extra.append("not empty")
        elif "minItems" in node or "maxItems" in node:
            extra.append("{}–{} entries".format(node.get("minItems", 0), node.get("maxItems", "")))
        return text + (", " + ", ".join(extra) if extra else "")
    return kind or ""


def default_text(node):
    if "default" in node:
        value = node["default"]
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return number_text(value)
        return "`" + json.dumps(value, ensure_ascii=False) .strip('"') + "`"
    return node.get("x-default", "–")


def live_text(rule):
    live, reason = rule
    if live:
        return "yes"
    return "no" + (f": {reason}" if reason else "")


def rows(node, path, rule, out):
    """Depth first: one row per key that holds a value (objects are walked, not listed)."""
    if "x-live" in node:
        rule = (node["x-live"], "")
    if "x-fixed" in node:
        rule = (False, node["x-fixed"])
    properties = node.get("properties")
    extra = node.get("additionalProperties")
    if properties is None and not isinstance(extra, dict):
        out.append((path, type_text(node), default_text(node), node.get("description", ""),
                    live_text(rule)))
        return
    for key, child in (properties or {}).items():
        rows(child, f"{path}.{key}" if path else key, rule, out)
    if isinstance(extra, dict):
        names = node.get("propertyNames", {}).get("enum")
        placeholder = "FIELD"
        if names:
            out.append((path, "object: " + names_text(names) + " → " + placeholder, "–",
                        node.get("description", ""), live_text(rule)))
        rows(extra, f"{path}.{placeholder}", rule, out)


def table(schema):
    out = []
    rows(schema, "", (False, ""), out)
    lines = ["| key | type | default (tgv3d / tgv2d) | meaning | live change |",
             "|---|---|---|---|---|"]
    for key, kind, default, meaning, live in out:
        cells = [f"`{key}`", kind, default, meaning, live]
        lines.append("| " + " | ".join(c.replace("\n", " ") for c in cells) + " |")
    return "\n".join(lines) + "\n"


def main():
    parser = argparse.ArgumentParser(description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("doc", help="docs/scenes.md")
    parser.add_argument("--sphles", required=True, help="the sphles program (prints the schema)")
    parser.add_argument("--check", action="store_true", help="exit 1 if the table differs")
    args = parser.parse_args()
    schema = json.loads(subprocess.run([args.sphles, "schema", "scene"], check=True,
                                       capture_output=True, text=True).stdout)
    with open(args.doc, encoding="utf-8") as f:
        text = f.read()
    if BEGIN not in text or END not in text:
        sys.exit(f"{args.doc}: no {BEGIN} ... {END} markers")
    head, rest = text.split(BEGIN, 1)
    _, tail = rest.split(END, 1)
    updated = head + BEGIN + "\n" + table(schema) + END + tail
    if args.check:
        if updated != text:
            sys.exit(f"{args.doc}: the table of scene keys differs from the scene schema; run "
                     f"scripts/scene_docs.py --sphles {args.sphles} {args.doc}")
        return
    if updated != text:
        with open(args.doc, "w", encoding="utf-8") as f:
            f.write(updated)


if __name__ == "__main__":
    main()
