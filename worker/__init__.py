"""The pdeanim worker: claims jobs from ``service.store``, runs each attempt in a child process."""
