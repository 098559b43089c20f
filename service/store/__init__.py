"""Storage shared by the API and the worker: metadata models, migrations, the job queue and the blob store."""
