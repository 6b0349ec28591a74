"""Runs a command, samples its resident set (VmRSS) and high-water mark (VmHWM) every 5 ms, prints the peak and
when the high-water mark rose (in steps of 50 MB above 2.5 GiB), then the command's last standard error.
Usage: python rss_trace.py COMMAND [ARG...]"""
import subprocess, sys, time
p = subprocess.Popen(sys.argv[1:], stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True)
t0 = time.time(); trace = []
while p.poll() is None:
    try:
        with open(f"/proc/{p.pid}/status") as f:
            for line in f:
                if line.startswith("VmRSS"):
                    rss = int(line.split()[1])
                if line.startswith("VmHWM"):
                    hwm = int(line.split()[1])
            trace.append((time.time() - t0, rss, hwm))
    except OSError:
        pass
    time.sleep(0.005)
err = p.stderr.read()
peak = max(trace, key=lambda x: x[1])
print(f"sampled peak {peak[1]/2**20:.3f} GiB at {peak[0]:.1f} s of {trace[-1][0]:.1f} s; "
      f"HWM {trace[-1][2]/2**20:.3f} GiB")
last = 0
for t, r, h in trace:
    if h > last + 50 * 1024 and h > 2.5 * 2**20:
        print(f"HWM {h/2**20:.3f} GiB at {t:.2f} s (rss {r/2**20:.3f})"); last = h
print(err[-1500:])
