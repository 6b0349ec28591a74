# session 25: stop chain5 once six windows scenes have 4096-spp references, then run chain6
cd /work/data
while [ ! -f train_g33_win_r4k/scene_0005/manifest.json ]; do sleep 10; done
pkill -f chain5.sh; pkill -f make_ref.py; sleep 3; rm -rf train_g33_win_r4k/*.tmp
bash s25/chain6.sh
