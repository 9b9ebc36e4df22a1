"""Route modules: ``jobs`` (the job resource) and ``system`` (health, metrics, OpenAPI)."""
