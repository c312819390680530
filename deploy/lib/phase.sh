# Phase timing for deploy/*.sh (sourced). `phase NAME` ends the running phase
# (printing `phase <name> <seconds> s`, the verification interface of README
# commands 1 and 2) and starts NAME; `phase_end` ends the running one.
# Wall time, from bash's EPOCHREALTIME (no external commands).
_phase_name=""
_phase_t0=0
_phase_us() { local t=${EPOCHREALTIME/[.,]/}; echo "$t"; }
phase_end() {
  [[ -n "$_phase_name" ]] || return 0
  local us=$(($(_phase_us) - _phase_t0))
  printf 'phase %s %d.%d s\n' "$_phase_name" $((us / 1000000)) $((us / 100000 % 10))
  _phase_name=""
}
phase() {
  phase_end
  _phase_name=$1
  _phase_t0=$(_phase_us)
}
# phase_since NAME T0: prints `phase NAME <seconds> s` for the time since T0
# (a `phase_now` value), e.g. a script's total.
phase_now() { _phase_us; }
phase_since() {
  local us=$(($(_phase_us) - $2))
  printf 'phase %s %d.%d s\n' "$1" $((us / 1000000)) $((us / 100000 % 10))
}
