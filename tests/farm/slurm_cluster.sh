#!/usr/bin/env bash
# Starts a real single-node Slurm cluster (slurmctld + slurmd, auth/none) and runs a command
# against it, all inside fresh Linux namespaces (network, PID, mount): nothing reaches or is
# reached from outside, and every daemon dies with the namespace when the command ends.
#   tests/farm/slurm_cluster.sh WORKDIR COMMAND [ARGS...]
# Exit status: the command's; 77 when this machine cannot run it (no Slurm, no namespaces).
set -uo pipefail
cluster_dir=$1; shift  # not "work": the command may use that name
for tool in slurmctld slurmd sbatch squeue scontrol unshare ip; do
  command -v "$tool" >/dev/null || { echo "SKIP: $tool is not installed (scripts/deps.sh installs slurm-wlm and iproute2)"; exit 77; }
done
if ! unshare --net --pid --fork --mount-proc true 2>/dev/null; then
  echo "SKIP: cannot create network and PID namespaces here (unshare --net --pid needs root or user namespaces)"
  exit 77
fi
mkdir -p "$cluster_dir"
cluster_dir=$(cd "$cluster_dir" && pwd)
exec unshare --net --pid --fork --mount-proc bash -s "$cluster_dir" "$@" <<'INNER'
set -uo pipefail
cluster=$1; shift  # not "work": the command may use that name
# Loopback only. glibc's getaddrinfo (AI_ADDRCONFIG, which Slurm uses) returns nothing while no
# interface but loopback has an address, so a veth pair with both ends inside this namespace
# gives it one; it leads nowhere.
ip link set lo up
ip link add rsfarm0 type veth peer name rsfarm1 && ip addr add 10.254.254.1/24 dev rsfarm0 && ip link set rsfarm0 up && ip link set rsfarm1 up \
  || { echo "SKIP: cannot create a veth pair in the namespace"; exit 77; }
mkdir -p "$cluster/state" "$cluster/spool" "$cluster/log"
cat > "$cluster/slurm.conf" <<CONF
ClusterName=reshutter-test
SlurmctldHost=localhost(127.0.0.1)
AuthType=auth/none
CredType=cred/none
SlurmUser=$(id -un)
SlurmdUser=root
StateSaveLocation=$cluster/state
SlurmdSpoolDir=$cluster/spool
SlurmctldPidFile=$cluster/slurmctld.pid
SlurmdPidFile=$cluster/slurmd.pid
SlurmctldLogFile=$cluster/log/slurmctld.log
SlurmdLogFile=$cluster/log/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core
MpiDefault=none
ReturnToService=2
JobCompType=jobcomp/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
MinJobAge=600
NodeName=localhost NodeAddr=127.0.0.1 CPUs=$(nproc) State=UNKNOWN
PartitionName=farm Nodes=localhost Default=YES MaxTime=INFINITE State=UP OverSubscribe=YES
CONF
export SLURM_CONF=$cluster/slurm.conf
slurmctld -D -i -f "$SLURM_CONF" >"$cluster/log/slurmctld.out" 2>&1 &
slurmd -D -f "$SLURM_CONF" -N localhost >"$cluster/log/slurmd.out" 2>&1 &
for _ in $(seq 100); do
  [ "$(timeout 5 sinfo --noheader -o %T 2>/dev/null)" = idle ] && break
  sleep 0.2
done
if [ "$(timeout 5 sinfo --noheader -o %T 2>/dev/null)" != idle ]; then
  echo "the Slurm cluster did not come up; its logs:"; tail -n 20 "$cluster"/log/*
  exit 1
fi
"$@"
rc=$?
[ $rc -eq 0 ] || { echo "--- slurmctld log"; tail -n 30 "$cluster/log/slurmctld.log"; }
exit $rc
INNER
