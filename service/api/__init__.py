"""The HTTP API: app factory (``app.create_app``), dependencies, response models and routes."""
