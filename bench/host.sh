# Sourced by the bench scripts: host_line prints the machine a figure was measured on, since the
# project's VM lands on different hosts between sessions (a Zen 5 and a Zen 4 differ by ~15 % on
# the same build): CPU model, family/model, vCPUs, the vector units the kernels pick, L2, load.
host_line() {
  local model family cpumodel l2 isa
  model=$(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2- | sed 's/^ //')
  family=$(grep -m1 'cpu family' /proc/cpuinfo | cut -d: -f2 | tr -d ' ')
  cpumodel=$(grep -m1 '^model[[:space:]]*:' /proc/cpuinfo | cut -d: -f2 | tr -d ' ')
  l2=$(getconf LEVEL2_CACHE_SIZE 2>/dev/null || echo 0)
  isa=scalar
  grep -qw avx2 /proc/cpuinfo && isa=AVX2
  grep -qw avx512bw /proc/cpuinfo && isa=AVX-512
  echo "host: ${model} (family ${family} model ${cpumodel}), $(nproc) vCPU, ${isa}, L2 $((l2 / 1024)) KB, load $(cut -d' ' -f1-3 /proc/loadavg)"
}
