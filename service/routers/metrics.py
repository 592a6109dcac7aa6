"""/metrics: the queue depth and the job counts for Prometheus (text exposition format).

Scraped without an API key, like the health probes (``prometheus.io/scrape`` annotations in
deploy/k8s/api.yaml). The figures come from the broker and the registry at each scrape, so
every API replica reports the same service-wide values: aggregate with ``max``, not ``sum``.
Worker autoscaling does not depend on this route: KEDA reads the Redis list itself
(deploy/k8s/worker-autoscaling.yaml).
"""
from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Response
from prometheus_client import CONTENT_TYPE_LATEST, CollectorRegistry, generate_latest
from prometheus_client.core import GaugeMetricFamily

from ..deps import Services, services
from ..registry import STATES

router = APIRouter(tags=["metrics"])
PATH = "/metrics"


class _Collector:
    """Reads the broker and the registry when Prometheus scrapes."""

    def __init__(self, svc: Services):
        self.svc = svc

    def collect(self):
        svc = self.svc
        queue = GaugeMetricFamily("hockle_queue_depth", "Job messages waiting in the broker "
                                  "queue (not yet taken by a worker).", labels=["queue"])
        broker_up = GaugeMetricFamily("hockle_broker_up", "1 when the broker answered this "
                                      "scrape, else 0.")
        try:
            queue.add_metric([svc.settings.queue], svc.enqueuer.queue_depth())
            broker_up.add_metric([], 1)
        except Exception:  # noqa: BLE001 - reported as broker_up 0
            broker_up.add_metric([], 0)
        jobs = GaugeMetricFamily("hockle_jobs", "Jobs in the registry by state.",
                                 labels=["state"])
        workers = GaugeMetricFamily("hockle_workers_seen", "Workers whose heartbeat came "
                                    "within HOCKLE_WORKER_SEEN_WINDOW.")
        registry_up = GaugeMetricFamily("hockle_registry_up", "1 when the registry answered "
                                        "this scrape, else 0.")
        try:
            counts = svc.registry.counts()
            seen = len(svc.registry.workers_seen(svc.settings.worker_seen_window))
        except Exception:  # noqa: BLE001 - reported as registry_up 0
            registry_up.add_metric([], 0)
        else:
            for state in STATES:
                jobs.add_metric([state], counts.get(state, 0))
            workers.add_metric([], seen)
            registry_up.add_metric([], 1)
        yield from (queue, broker_up, jobs, workers, registry_up)


@router.get(PATH, operation_id="get_metrics", summary="Prometheus metrics",
            response_class=Response,
            responses={200: {"content": {CONTENT_TYPE_LATEST: {}},
                             "description": "Prometheus text format"}})
def get_metrics(svc: Annotated[Services, Depends(services)]) -> Response:
    """``hockle_queue_depth``, ``hockle_jobs{state}``, ``hockle_workers_seen``,
    ``hockle_registry_up``, ``hockle_broker_up``."""
    registry = CollectorRegistry(auto_describe=False)
    registry.register(_Collector(svc))
    return Response(generate_latest(registry), media_type=CONTENT_TYPE_LATEST)
