"""The service around the flows: its automations and concurrency limits (``python -m deploy.service``)
and the reporter of stopped runs (``python -m deploy.reporter``), run from the repository root by
``deploy/serve.sh``."""
