#!/usr/bin/env bash
# Build the hockle image, push it to a registry the cluster can pull from, and pin the
# Kubernetes manifests (deploy/k8s) to exactly that image.
#
#   deploy/build-push.sh REGISTRY/REPO [TAG]      e.g. deploy/build-push.sh ghcr.io/lab/hockle
#   kubectl apply -k deploy/k8s
#
# TAG defaults to `git describe --always --dirty` (a tree with uncommitted changes is refused
# unless ALLOW_DIRTY=1). After the push the kustomization names the image by its digest,
# so every node runs the same bytes whatever later happens to the tag.
set -euo pipefail
root="$(cd "$(dirname "$0")/.." && pwd)"
repo="${1:?usage: deploy/build-push.sh REGISTRY/REPO [TAG] (e.g. ghcr.io/lab/hockle)}"
tag="${2:-$(git -C "$root" describe --always --dirty)}"
if [[ "$tag" == *-dirty && "${ALLOW_DIRTY:-0}" != 1 ]]; then
  echo "build-push: the tree has uncommitted changes ($tag); commit them or set ALLOW_DIRTY=1" >&2
  exit 2
fi
docker build -f "$root/deploy/Dockerfile" -t "$repo:$tag" "$root"
docker push "$repo:$tag"
ref="$(docker inspect --format '{{range .RepoDigests}}{{println .}}{{end}}' "$repo:$tag" \
       | grep -m1 "^$repo@" || true)"
digest="${ref#*@}"
if [[ "$digest" == sha256:* ]]; then
  python3 "$root/deploy/set_image.py" "$root/deploy/k8s/kustomization.yaml" "$repo" "$tag" "$digest"
else
  python3 "$root/deploy/set_image.py" "$root/deploy/k8s/kustomization.yaml" "$repo" "$tag"
fi
echo "build-push: pushed $repo:$tag${digest:+ ($digest)}; now: kubectl apply -k deploy/k8s"
