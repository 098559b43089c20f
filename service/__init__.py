"""The pdeanim web service: FastAPI API (``service.api``), storage shared with the worker
(``service.store``)."""
