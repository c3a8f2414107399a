"""siteline's Prefect flows (``pipeline``), what they show in the UI (``ui``) and their task runners
(``runner``): run from the repository root, where Prefect's deployments (deploy/prefect.yaml) load
``flows/pipeline.py`` and it imports the rest as ``flows.*``."""
