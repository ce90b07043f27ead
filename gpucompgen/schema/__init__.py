"""JSON Schemas of gpucompgen's YAML files, for editors (yaml-language-server) and tools.

The loader (model/) is what decides; these schemas describe the same language so an
editor can flag problems while typing.  They are generated from the loader's own key
tables and enums by generate.py (``python -m gpucompgen.schema.generate --write``), and
tests/test_schema.py checks that the checked-in files are what it generates.
"""

from __future__ import annotations

import json
from importlib import resources

MODEL = "model.schema.json"
TYPES = "types.schema.json"


def schema_text(name: str = MODEL) -> str:
    return resources.files(__name__).joinpath(name).read_text(encoding="utf-8")


def schema(name: str = MODEL) -> dict:
    return json.loads(schema_text(name))
