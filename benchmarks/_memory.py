"""Peak resident memory of a benchmark, sampled in a thread (this process and all its children)."""

import threading

import psutil


class MemoryMonitor:
    """Peak summed RSS of this process and all its children, sampled in a thread."""

    def __init__(self, interval=0.2):
        self.proc = psutil.Process()
        self.interval = interval
        self.peak_total = 0
        self.peak_main = 0
        self.peak_child = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True)

    def _sample(self):
        total = main = self.proc.memory_info().rss
        child = 0
        for ch in self.proc.children(recursive=True):
            try:
                r = ch.memory_info().rss
            except psutil.Error:
                continue
            total += r
            child = max(child, r)
        self.peak_total = max(self.peak_total, total)
        self.peak_main = max(self.peak_main, main)
        self.peak_child = max(self.peak_child, child)

    def _run(self):
        while not self._stop.is_set():
            self._sample()
            self._stop.wait(self.interval)

    def __enter__(self):
        self._thread.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        self._thread.join()
        self._sample()
