"""Keep docker-compose.yml, deploy/Dockerfile and deploy/k8s honest: no Docker engine runs here,
so parse them and check every command, port, variable and volume against what the code reads."""
from __future__ import annotations

import argparse
import importlib.util
import re
import shlex
from pathlib import Path
from urllib.parse import urlparse

import pytest
import yaml

from service.settings import Settings
from svc_support import REPO

COMPOSE = REPO / "docker-compose.yml"
DOCKERFILE = REPO / "deploy" / "Dockerfile"
K8S = REPO / "deploy" / "k8s"
FIELDS = {f"HOCKLE_{name.upper()}" for name in Settings.model_fields}


def _compose() -> dict:
    return yaml.safe_load(COMPOSE.read_text())


def _k8s() -> list[dict]:
    docs = []
    for path in sorted(K8S.glob("*.yaml")):
        docs += [d for d in yaml.safe_load_all(path.read_text()) if d]
    return docs


def _by_kind(kind: str) -> dict[str, dict]:
    return {d["metadata"]["name"]: d for d in _k8s() if d["kind"] == kind}


def _dockerfile_env() -> dict[str, str]:
    text = DOCKERFILE.read_text().replace("\\\n", " ")
    env = {}
    for line in text.splitlines():
        if line.startswith("ENV "):
            for key, value in re.findall(r"(\w+)=(\S+)", line):
                env[key] = value
    return env


def _settings_from(env: dict[str, str]) -> Settings:
    kwargs = {k[len("HOCKLE_"):].lower(): v for k, v in env.items() if k.startswith("HOCKLE_")}
    return Settings(**kwargs)


def _check_command(command: list[str]) -> None:
    """A command of ours must be `python -m service|worker ARGS` whose ARGS the CLI accepts."""
    assert command[:2] == ["python", "-m"], command
    module, args = command[2], command[3:]
    assert module in ("service", "worker"), command
    assert importlib.util.find_spec(f"{module}.__main__") is not None
    parser = argparse.ArgumentParser(exit_on_error=False)
    if module == "service":
        from service.serve import add_arguments
    else:
        from worker.cli import add_arguments
    add_arguments(parser)
    parser.parse_args(args)


def _variables_in(text: str) -> set[str]:
    return set(re.findall(r"\bHOCKLE_[A-Z_]+\b", text))


@pytest.mark.parametrize("path", [COMPOSE, DOCKERFILE, *sorted(K8S.glob("*.yaml")),
                                  REPO / "docs" / "service.md", REPO / "docs" / "README-service.md"],
                         ids=lambda p: p.name)
def test_every_hockle_variable_named_is_a_setting(path: Path):
    unknown = _variables_in(path.read_text()) - FIELDS
    assert not unknown, f"{path.name} names variables the code never reads: {unknown}"


def test_docs_table_lists_every_setting_with_its_default():
    text = (REPO / "docs" / "service.md").read_text()
    rows = {m.group(1): m.group(2) for m in re.finditer(r"^\| `(HOCKLE_[A-Z_]+)` \| ([^|]*) \|",
                                                        text, re.M)}
    assert set(rows) == FIELDS
    for name, field in Settings.model_fields.items():
        if field.default is not None and not isinstance(field.default, Path):
            assert str(field.default) in rows[f"HOCKLE_{name.upper()}"], name


def test_compose_services_commands_ports_volumes():
    compose = _compose()
    services = compose["services"]
    assert {"redis", "postgres", "api", "worker", "flower"} <= set(services)
    for name in ("redis", "postgres", "api", "worker"):
        assert "healthcheck" in services[name], name

    redis_cmd = services["redis"]["command"]
    assert redis_cmd[0] == "redis-server"
    assert redis_cmd[redis_cmd.index("--appendonly") + 1] == "yes"
    assert redis_cmd[redis_cmd.index("--maxmemory-policy") + 1] == "noeviction"

    api, worker = services["api"], services["worker"]
    _check_command(api["command"])
    _check_command(worker["command"])
    assert api["command"][2] == "service" and worker["command"][2] == "worker"
    for svc in (api, worker):
        assert svc["build"]["dockerfile"] == "deploy/Dockerfile"
        assert (REPO / svc["build"]["context"] / svc["build"]["dockerfile"]).exists()
    assert worker["deploy"]["replicas"] >= 2

    api_env = {**_dockerfile_env(), **{k: str(v) for k, v in api["environment"].items()}}
    worker_env = {**_dockerfile_env(), **{k: str(v) for k, v in worker["environment"].items()}}
    api_settings, worker_settings = _settings_from(api_env), _settings_from(worker_env)
    # the port the API binds is the one published and probed
    published = api["ports"][0].split(":")
    assert int(published[-1]) == api_settings.port
    assert f"127.0.0.1:{api_settings.port}/v1/health" in " ".join(api["healthcheck"]["test"])
    assert api_settings.host == "0.0.0.0"
    # API and workers agree on broker, registry, queue and result store
    for attr in ("broker_url", "registry_url", "queue", "results_dir"):
        assert getattr(api_settings, attr) == getattr(worker_settings, attr), attr
    assert not api_settings.embedded
    broker = urlparse(api_settings.broker_url)
    assert broker.scheme == "redis" and broker.hostname in services and broker.port == 6379
    db = urlparse(api_settings.database_url)
    pg_env = services["postgres"]["environment"]
    assert db.hostname in services and db.username == pg_env["POSTGRES_USER"]
    assert db.path.lstrip("/") == pg_env["POSTGRES_DB"]
    # the result volume is mounted where both read HOCKLE_RESULTS_DIR, and declared
    for svc, settings in ((api, api_settings), (worker, worker_settings)):
        mounts = dict(m.split(":")[::-1] for m in svc["volumes"])
        assert mounts[str(settings.results_dir)] == "results"
    for svc in services.values():
        for mount in svc.get("volumes", []):
            assert mount.split(":")[0] in compose["volumes"], mount

    flower = services["flower"]
    assert flower["profiles"] == ["monitoring"]
    cmd = " ".join(flower["command"])
    assert "--basic-auth=" in cmd and "flower" in flower["command"]
    assert f"--broker={api_settings.broker_url}" in cmd
    assert "flower" in DOCKERFILE.read_text()  # the image it runs has flower installed
    # its own healthcheck on Flower's port (the image's HEALTHCHECK probes the API's :8000),
    # healthy on any HTTP answer (its basic auth answers 401), failing when nothing listens
    check = flower["healthcheck"]["test"]
    assert check[:3] == ["CMD", "python", "-c"] and "127.0.0.1:5555" in check[3]
    import http.server
    import subprocess
    import sys
    import threading

    class Unauthorised(http.server.BaseHTTPRequestHandler):
        def do_GET(self):
            self.send_response(401)
            self.end_headers()

        def log_message(self, *args):
            pass

    probe = check[3].replace("127.0.0.1:5555", "127.0.0.1:{port}")
    server = http.server.HTTPServer(("127.0.0.1", 0), Unauthorised)
    port = server.server_address[1]
    threading.Thread(target=server.serve_forever, daemon=True).start()
    try:
        assert subprocess.run([sys.executable, "-c", probe.format(port=port)]).returncode == 0
    finally:
        server.shutdown()
        server.server_close()
    assert subprocess.run([sys.executable, "-c", probe.format(port=port)],
                          capture_output=True).returncode != 0


def test_no_default_passwords_and_the_api_requires_keys():
    """Secrets are required variables (${VAR:?message}), never defaults: a forgotten one stops
    `docker compose`, it does not start a database or Flower with a password from this file."""
    text = COMPOSE.read_text()
    assert not re.search(r"\$\{(POSTGRES_PASSWORD|FLOWER_PASSWORD|HOCKLE_API_KEYS)(:?-)", text)
    services = _compose()["services"]
    assert services["postgres"]["environment"]["POSTGRES_PASSWORD"].startswith(
        "${POSTGRES_PASSWORD:?")
    assert "${FLOWER_PASSWORD:?" in " ".join(services["flower"]["command"])
    # the API binds 0.0.0.0: it gets keys, and the same secret in Kubernetes
    assert services["api"]["environment"]["HOCKLE_API_KEYS"].startswith("${HOCKLE_API_KEYS:?")
    (container,) = _by_kind("Deployment")["hockle-api"]["spec"]["template"]["spec"]["containers"]
    env = {e["name"]: e for e in container["env"]}
    assert env["HOCKLE_API_KEYS"]["valueFrom"]["secretKeyRef"]["name"] == "hockle-api-keys"


def test_dockerfile_copies_the_packages_and_exposes_the_port():
    text = DOCKERFILE.read_text()
    env = _dockerfile_env()
    settings = _settings_from(env)
    assert f"EXPOSE {settings.port}" in text
    import tomllib

    # pyproject's readme is needed by any build of the distribution, not only this image
    readme = tomllib.loads((REPO / "pyproject.toml").read_text())["project"]["readme"]
    for line in text.splitlines():
        if line.startswith("COPY "):
            for source in shlex.split(line)[1:-1]:
                assert (REPO / source).exists() or source == readme, source
    for package in ("solver", "worker", "service", "hockle"):
        assert f"COPY {package} ./{package}" in text
    cmd = re.search(r'^CMD (\[.*\])', text, re.M).group(1)
    _check_command(yaml.safe_load(cmd))
    assert f"127.0.0.1:{settings.port}/v1/health" in text


def test_kubernetes_manifests():
    config = _by_kind("ConfigMap")["hockle-config"]["data"]
    secret_env = {"HOCKLE_DATABASE_URL": "postgresql://u:p@db:5432/hockle"}
    settings = _settings_from({**config, **secret_env})
    deployments = _by_kind("Deployment")
    api, worker = deployments["hockle-api"], deployments["hockle-worker"]
    assert worker["spec"]["replicas"] >= 2

    pvc = _by_kind("PersistentVolumeClaim")["hockle-results"]
    assert "ReadWriteMany" in pvc["spec"]["accessModes"]

    for dep in (api, worker):
        pod = dep["spec"]["template"]["spec"]
        (container,) = pod["containers"]
        _check_command(container["command"] + container.get("args", []))
        assert container["resources"]["requests"]["cpu"] and container["resources"]["requests"]["memory"]
        assert {"configMapRef": {"name": "hockle-config"}} in container["envFrom"]
        names = {e["name"] for e in container.get("env", [])}
        assert "HOCKLE_DATABASE_URL" in names
        volumes = {v["name"]: v for v in pod["volumes"]}
        mounts = {m["mountPath"]: m["name"] for m in container["volumeMounts"]}
        results = mounts[str(settings.results_dir)]
        assert volumes[results]["persistentVolumeClaim"]["claimName"] == "hockle-results"
        labels = dep["spec"]["template"]["metadata"]["labels"]
        assert dep["spec"]["selector"]["matchLabels"].items() <= labels.items()

    (container,) = api["spec"]["template"]["spec"]["containers"]
    ports = {p["name"]: p["containerPort"] for p in container["ports"]}
    assert ports["http"] == settings.port
    for probe in ("readinessProbe", "livenessProbe"):
        get = container[probe]["httpGet"]
        assert get["path"].split("?")[0] == "/v1/health"
        assert get["port"] in ("http", settings.port)
    service = _by_kind("Service")["hockle-api"]
    assert service["spec"]["ports"][0]["targetPort"] in ("http", settings.port)
    assert service["spec"]["selector"].items() <= \
        api["spec"]["template"]["metadata"]["labels"].items()

    broker = urlparse(settings.broker_url)
    redis_service = _by_kind("Service")[broker.hostname]
    assert redis_service["spec"]["ports"][0]["port"] == broker.port
    redis = _by_kind("StatefulSet")["hockle-redis"]["spec"]["template"]["spec"]["containers"][0]
    assert "noeviction" in redis["args"] and "--appendonly" in redis["args"]
    assert settings.visibility_timeout > settings.time_limit_max

    kustomization = yaml.safe_load((K8S / "kustomization.yaml").read_text())
    listed = set(kustomization["resources"])
    assert listed == {p.name for p in K8S.glob("*.yaml")} - {"kustomization.yaml"}


def test_health_route_exists_in_the_app():
    from service.routers.health import router

    assert "/health" in {r.path for r in router.routes}


def _stub_docker(bin_dir: Path, log: Path, digest: str) -> None:
    """A `docker` on PATH that records its arguments and answers `inspect` with a digest."""
    bin_dir.mkdir()
    stub = bin_dir / "docker"
    stub.write_text("#!/bin/sh\n"
                    f'echo "$@" >> "{log}"\n'
                    'if [ "$1" = inspect ]; then echo "ghcr.io/lab/hockle@' + digest + '"; fi\n')
    stub.chmod(0o755)


def test_build_push_pins_the_manifests_to_the_pushed_image(tmp_path):
    """deploy/build-push.sh builds with the Dockerfile, pushes, and rewrites the
    kustomization to the pushed image by digest (docker stubbed: no engine runs in CI)."""
    import os
    import shutil
    import subprocess

    root = tmp_path / "repo"
    shutil.copytree(REPO / "deploy", root / "deploy")
    log = tmp_path / "docker.log"
    digest = "sha256:" + "ab" * 32
    _stub_docker(tmp_path / "bin", log, digest)
    env = dict(os.environ, PATH=f"{tmp_path / 'bin'}:{os.environ['PATH']}")
    out = subprocess.run([str(root / "deploy" / "build-push.sh"), "ghcr.io/lab/hockle", "v1.2"],
                         env=env, capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
    calls = log.read_text().splitlines()
    assert calls[0] == (f"build -f {root}/deploy/Dockerfile -t ghcr.io/lab/hockle:v1.2 {root}")
    assert calls[1] == "push ghcr.io/lab/hockle:v1.2"
    kust = yaml.safe_load((root / "deploy" / "k8s" / "kustomization.yaml").read_text())
    assert kust["images"] == [{"name": "hockle", "newName": "ghcr.io/lab/hockle",
                               "digest": digest}]
    assert kust["resources"] == yaml.safe_load(
        (REPO / "deploy" / "k8s" / "kustomization.yaml").read_text())["resources"]
    assert (root / "deploy" / "k8s" / "kustomization.yaml").read_text().startswith("# ")
    # a tag of a tree with uncommitted changes is refused unless asked for
    out = subprocess.run([str(root / "deploy" / "build-push.sh"), "ghcr.io/lab/hockle",
                          "0a1b2c3-dirty"], env=env, capture_output=True, text=True)
    assert out.returncode == 2 and "uncommitted" in out.stderr


@pytest.mark.parametrize("args, why", [
    (["ghcr.io/Lab/Hockle", "v1"], "not an image repository"),
    (["ghcr.io/lab/hockle", "v 1"], "not an image tag"),
    (["ghcr.io/lab/hockle", "v1", "sha256:xyz"], "not an image digest"),
])
def test_set_image_refuses_bad_references(tmp_path, args, why):
    import shutil
    import subprocess
    import sys

    kust = tmp_path / "kustomization.yaml"
    shutil.copy(REPO / "deploy" / "k8s" / "kustomization.yaml", kust)
    out = subprocess.run([sys.executable, str(REPO / "deploy" / "set_image.py"), str(kust),
                          *args], capture_output=True, text=True)
    assert out.returncode == 2 and why in out.stderr
    assert kust.read_text() == (REPO / "deploy" / "k8s" / "kustomization.yaml").read_text()


AUTOSCALING = REPO / "deploy" / "k8s-autoscaling"


def test_worker_autoscaling_reads_the_queue_the_workers_take_jobs_from():
    """The KEDA ScaledObject scales the worker Deployment on the Redis list that holds the
    waiting job messages: the broker Service, database and queue name the code uses."""
    (scaled,) = [d for d in yaml.safe_load_all(
        (AUTOSCALING / "worker-scaledobject.yaml").read_text()) if d]
    assert (scaled["apiVersion"], scaled["kind"]) == ("keda.sh/v1alpha1", "ScaledObject")
    spec = scaled["spec"]
    assert spec["scaleTargetRef"]["name"] in _by_kind("Deployment")
    assert spec["scaleTargetRef"]["name"] == "hockle-worker"
    assert 1 <= spec["minReplicaCount"] <= spec["maxReplicaCount"]
    (trigger,) = spec["triggers"]
    assert trigger["type"] == "redis"
    config = _by_kind("ConfigMap")["hockle-config"]["data"]
    settings = _settings_from({**config, "HOCKLE_DATABASE_URL": "postgresql://u:p@db/h"})
    broker = urlparse(settings.broker_url)
    meta = trigger["metadata"]
    assert meta["listName"] == settings.queue
    host, port = meta["address"].rsplit(":", 1)
    assert host.split(".")[0] == broker.hostname and int(port) == broker.port
    assert host.endswith(".svc.cluster.local")   # KEDA connects from its own namespace
    assert int(meta["databaseIndex"]) == int(broker.path.strip("/") or 0)
    kustomization = yaml.safe_load((AUTOSCALING / "kustomization.yaml").read_text())
    assert "../k8s" in kustomization["resources"]
    assert "worker-scaledobject.yaml" in kustomization["resources"]


@pytest.mark.parametrize("directory", [K8S, AUTOSCALING], ids=["base", "autoscaling"])
def test_kustomize_builds_the_manifests(directory):
    """`kubectl kustomize` (kustomize is built into kubectl) renders both; with autoscaling the
    worker Deployment has no fixed replica count (KEDA's HPA sets it) and the ScaledObject is
    there. kubeconform validates the output where it is installed (with its schemas)."""
    import shutil
    import subprocess

    kubectl = shutil.which("kubectl")
    if kubectl is None:
        pytest.skip("kubectl is not on PATH")
    rendered = subprocess.run([kubectl, "kustomize", str(directory)], check=True,
                              capture_output=True, text=True, timeout=60).stdout
    docs = [d for d in yaml.safe_load_all(rendered) if d]
    kinds = {(d["kind"], d["metadata"]["name"]) for d in docs}
    assert ("Deployment", "hockle-worker") in kinds and ("Deployment", "hockle-api") in kinds
    worker = next(d for d in docs if (d["kind"], d["metadata"]["name"]) ==
                  ("Deployment", "hockle-worker"))
    if directory == AUTOSCALING:
        assert ("ScaledObject", "hockle-worker") in kinds
        assert "replicas" not in worker["spec"]
    else:
        assert not any(kind == "ScaledObject" for kind, _ in kinds)
        assert worker["spec"]["replicas"] >= 2
    kubeconform = shutil.which("kubeconform")
    if kubeconform is not None:
        result = subprocess.run([kubeconform, "-strict", "-summary", "-ignore-missing-schemas",
                                 "-"], input=rendered, capture_output=True, text=True,
                                timeout=120)
        assert result.returncode == 0, result.stdout + result.stderr
