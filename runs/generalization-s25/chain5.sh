# session 25: train_g33_win (windows, v6/v7's training family with refraction) with 4096-spp references, scene by
# scene (resumable: done scenes are skipped), for a later fine-tune on cleaner references
cd /work/data
. /work/main/.venv/bin/activate
export NUMPY_MADVISE_HUGEPAGE=0
mkdir -p train_g33_win_r4k
python /work/main/runs/generalization-s25/make_ref.py train_g33_win train_g33_win_r4k 4096 >> s25/make_ref_win.log 2>&1
touch s25/chain5.done
