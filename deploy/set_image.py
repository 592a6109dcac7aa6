"""Point a kustomization's ``hockle`` image at a pushed image (used by deploy/build-push.sh).

    python deploy/set_image.py deploy/k8s/kustomization.yaml REGISTRY/REPO TAG [DIGEST]

Sets the ``images:`` entry named ``hockle`` to ``newName: REGISTRY/REPO`` and ``newTag: TAG``
(or ``digest: sha256:...`` when DIGEST is given, which pins the exact image the cluster
pulls), keeping the rest of the file; the same edit as ``kustomize edit set image``, without
needing the kustomize binary. Exit status 2 with a message on a bad argument or file.
"""
from __future__ import annotations

import re
import sys
from pathlib import Path

import yaml

NAME = "hockle"


def set_image(path: Path, new_name: str, tag: str, digest: str | None = None) -> dict:
    """Rewrite the kustomization at ``path``; returns the new ``images`` entry."""
    if not re.fullmatch(r"[a-z0-9]+([._/:-][a-z0-9]+)*", new_name):
        raise ValueError(f"not an image repository: {new_name!r} (e.g. ghcr.io/lab/hockle)")
    if not re.fullmatch(r"[A-Za-z0-9_][A-Za-z0-9_.-]{0,127}", tag):
        raise ValueError(f"not an image tag: {tag!r}")
    if digest is not None and not re.fullmatch(r"sha256:[0-9a-f]{64}", digest):
        raise ValueError(f"not an image digest: {digest!r} (sha256:<64 hex>)")
    text = path.read_text()
    doc = yaml.safe_load(text)
    if not isinstance(doc, dict) or doc.get("kind") != "Kustomization":
        raise ValueError(f"{path} is not a kustomization")
    entry = {"name": NAME, "newName": new_name}
    entry.update({"digest": digest} if digest else {"newTag": tag})
    images = [i for i in doc.get("images") or [] if i.get("name") != NAME] + [entry]
    doc["images"] = images
    head = "".join(line + "\n" for line in text.splitlines() if line.startswith("#"))
    path.write_text(head + yaml.safe_dump(doc, sort_keys=False))
    return entry


def main(argv: list[str]) -> int:
    if len(argv) not in (3, 4):
        print(__doc__.strip().splitlines()[2].strip(), file=sys.stderr)
        return 2
    try:
        entry = set_image(Path(argv[0]), argv[1], argv[2], argv[3] if len(argv) == 4 else None)
    except (OSError, ValueError, yaml.YAMLError) as exc:
        print(f"set_image: {exc}", file=sys.stderr)
        return 2
    print(f"{argv[0]}: image {NAME} -> {entry}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
