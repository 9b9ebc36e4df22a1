"""voxelastic job service: simulation jobs over HTTP, run by worker processes.

The life of a job, module by module::

    POST /jobs        api.routes.jobs -> jobs.submit -> admission.admit (422/413 before work):
                      admission.check_submission in a sandbox child (memory + time limits)
                      storage.save_mesh, store.create (status queued), queue.enqueue
    a worker slot     queue.LocalQueue (or celery_app.run_job) -> store.claim
                      worker.Supervisor.run -> runner.worker_main in a spawned process
                      (engine.pipeline.run -> engine.output.write_result into a staging directory)
                      limits, cancellation, progress -> store; storage.publish -> store.succeed
    GET /jobs/{id}    api.routes.jobs, api.events (server-sent events), FileResponse (Range)

``settings.Settings`` holds every option (``VOXELASTIC_*``); ``server.serve`` is
``voxelastic serve``. With tokens, ``api.deps.require_token`` names the tenant (a hash of the
token) and ``store.get_owned``/``store.list`` show a job only to it (and to admin tokens).
Imports flow one way: api -> jobs/queue/worker -> store/storage -> db;
only ``runner`` (inside worker processes) reaches into the engine's solver, and Taichi is never
imported here.
"""
