"""The pdeanim worker: claims jobs from ``pdeanim_service.store``, runs each attempt in a child process."""
