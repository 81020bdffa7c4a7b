#!/bin/bash
# Per language: new + build + test + 300 cycles in the exit-lab network (machine time only).
# Run from a fresh clone after `cargo build --release`.
SF=${SF:-$PWD/target/release/skillfab}
WORK=${WORK:-/tmp/skillfab-newcomer}
rm -rf "$WORK" && mkdir -p "$WORK" && cd "$WORK"
for lang in rust c python cpp; do
  name=mine_$lang
  t0=$(date +%s.%N)
  $SF new skill $name --lang $lang > /dev/null || exit 1
  cd $name
  case $lang in
    rust) cargo build --release -q 2>/dev/null && cargo test --release -q > test.out 2>&1 ;;
    c|cpp) make -s > /dev/null && ./test.sh > test.out ;;
    python) ./test.sh > test.out ;;
  esac
  ok=$?
  t1=$(date +%s.%N)
  runs=$($SF up launch.toml --cycles 300 --json --domain nc-$lang 2>/dev/null | python3 -c "import json,sys; r=json.load(sys.stdin); print([s['runs'] for s in r['skills'] if s['name']=='$name'][0])")
  t2=$(date +%s.%N)
  echo "$lang: new+build+test $(echo "$t1-$t0"|bc) s (ok=$ok), 300 cycles in the network $(echo "$t2-$t1"|bc) s, its runs $runs; $(tail -1 test.out)"
  cd ..
done
