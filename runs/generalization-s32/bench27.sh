# Issue 27's figures on this session's machine (an Intel AVX-512 VM with AMX, not sessions 24-31's AMD one), one
# after another with nothing else running: the cross-frame ratio (v8 against xg-v8, 480x270, medians of three
# interleaved rounds), the AOV pass, and bench/denoise.py's own 1080p synth frame. (The held-out 1080p frame and
# bench/rana.py ran on their own earlier: README section 2.)
cd /work/main && . .venv/bin/activate
python bench/shot.py --size 480x270 --single cpu-small-pdl-gza-v8 --cross cpu-small-pdl-gza-xg-v8 --repeat 3
python bench/aov.py
python bench/denoise.py --real ""
