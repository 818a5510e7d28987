# Sourced by every experiment harness in this folder: where the package, the umvs tool and the
# shared data are. Environment: UMVS (the tool), UMVS_SHARED_DATA or SHARED (../shared/data).
experiments_dir="$(cd "$(dirname "${BASH_SOURCE[0]}")" && pwd)"
REPO="$(cd "$experiments_dir/../.." && pwd)"
UMVS="${UMVS:-$REPO/build/devel/lib/unsup_mvs/umvs}"
SHARED="${SHARED:-${UMVS_SHARED_DATA:-$REPO/../shared/data}}"

# Stops the calling script with a message naming what to run when the tool is missing.
require_umvs() {
  [[ -x "$UMVS" ]] || { echo "$(basename "$0"): no umvs at $UMVS (bash scripts/build.sh)" >&2; exit 1; }
}
