# The shipped default against OIDN's prefiltered aux in its prior and in the baseline, on the held-out sets as they
# are rendered (gen.sh); one set at a time, each after its render
. "$(dirname "${BASH_SOURCE[0]}")/common.sh"
M=cpu-small-pdl-gza-v8
for s in heldout_g1int8_box heldout_g1int8_boxsob heldout_g1sg8_boxsob heldout_g1int8 heldout_g1fog_boxsob \
         heldout_g1sg8; do
  while [ ! -f s31/$s.done ]; do sleep 20; done
  ev v8 $s $M
  evc prior cp $s $M
  evc baseline cb $s $M
done
touch s31/chain1.done
