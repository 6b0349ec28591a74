# Users' files without guides or without the diffuse/specular split (the real files of ../shared/data/deep-real
# are R G B A Z alone): the shipped default against flat OIDN on the same reduced files (OIDN without guides too),
# session 15's perturb.py on three held-out sets at 4 and 16 spp: base (a copy), noaux (no albedo, no normal),
# rgbaonly (R G B A Z ZBack only).
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
for s in heldout_g1int8_box heldout_g1int8 heldout_g1sg8_boxsob; do
  for spp in 4 16; do
    for kind in base noaux rgbaonly; do
      d=red32_${kind}_${spp}_$s
      [ -f $S/$d.done ] || { python $R/bin-merge-s15/perturb.py $s $d $kind $spp > /dev/null && touch $S/$d.done; }
      ev v8 $d cpu-small-pdl-gza-v8
    done
  done
done
touch $S/chain3.done
