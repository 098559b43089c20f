"""The pdeanim web service: FastAPI API (``pdeanim_service.api``), storage shared with the worker
(``pdeanim_service.store``)."""
