#!/usr/bin/env bash
# Fails on an #include that breaks the library's layer order (docs/design.md, "Layers").
#
#   tools/scripts/check_layers.sh [ROOT]     (`make layer-check`; ROOT defaults to this checkout)
#
# The layers and the layers each one may use come from cmake/CovoxLayerTable.cmake, the table the
# build makes its per-layer targets from. A layer's files are include/covoxslam/<layer>/,
# src/<layer>/ and cuda/<layer>/. In them, every
#   #include "covoxslam/<other>/..."   (or <covoxslam/<other>/...>)
# must name the layer itself or one it uses, and not another layer's internal/ folder (its
# implementation details). Any other quoted include is refused too: a relative path
# ("../pipeline/...") would bypass the rule. A folder that is not in the table is an error, so a
# new layer cannot be added without a rule. Prints one line per violation (file:line, the include,
# the rule broken) and exits 1 if there is any.
set -euo pipefail
ROOT=$(cd "${1:-$(dirname "$0")/../..}" && pwd)
TABLE=cmake/CovoxLayerTable.cmake
cd "$ROOT"

declare -A uses=()
while IFS=: read -r layer used; do
  uses[$layer]=" ${used# } "
done < <(cmake -P "$TABLE")
[ "${#uses[@]}" -gt 0 ] || { echo "check_layers: no layers read from $TABLE" >&2; exit 2; }

violations=0
report() {  # file:line, the include line, the rule
  echo "check_layers: $1: $2: $3" >&2
  violations=$((violations + 1))
}

for top in include/covoxslam src cuda; do
  for folder in "$top"/*/; do
    [ -d "$folder" ] || continue
    name=$(basename "$folder")
    [ -n "${uses[$name]+set}" ] ||
      report "$folder" "(folder)" "'$name' is not a layer of $TABLE; add it there with the layers it uses"
  done
done

# Every #include line of the given layer's files, checked against the layer's row of the table.
check_layer() {
  local layer=$1 file rest location text target allowed rule
  local folders=()
  for folder in include/covoxslam/$layer src/$layer cuda/$layer; do
    [ -d "$folder" ] && folders+=("$folder")
  done
  [ "${#folders[@]}" -gt 0 ] || return 0
  while IFS= read -r hit; do
    file=${hit%%:*}
    rest=${hit#*:}
    location=$file:${rest%%:*}
    text=${rest#*:}
    text=${text#"${text%%[![:space:]]*}"}  # without leading blanks
    if [[ $text =~ ^#[[:space:]]*include[[:space:]]*[\"\<]covoxslam/([^/\"\>]+)/(internal/)? ]]; then
      target=${BASH_REMATCH[1]}
      [ "$target" = "$layer" ] && continue
      allowed=${uses[$layer]# }
      allowed=${allowed% }
      rule="layer '$layer' may include only itself and [$allowed] ($TABLE)"
      if [ -z "${uses[$target]+set}" ]; then
        report "$location" "$text" "'$target' is not a layer; $rule"
      elif [[ ${uses[$layer]} != *" $target "* ]]; then
        report "$location" "$text" "upward include of layer '$target'; $rule"
      elif [ -n "${BASH_REMATCH[2]}" ]; then
        report "$location" "$text" "internal/ headers are private to layer '$target'; include its public headers"
      fi
    elif [[ $text =~ ^#[[:space:]]*include[[:space:]]*\"covoxslam/[^/\"]+\" ]]; then
      [ "$layer" = ros ] ||
        report "$location" "$text" "generated ROS message headers belong to the ros layer, not '$layer'"
    elif [[ $text =~ ^#[[:space:]]*include[[:space:]]*\" ]]; then
      report "$location" "$text" "quoted includes must name covoxslam/<layer>/...; a relative path bypasses the layer rule"
    fi
  done < <(grep -rnE '^[[:space:]]*#[[:space:]]*include' "${folders[@]}" || true)
}

for layer in "${!uses[@]}"; do
  check_layer "$layer"
done

if [ "$violations" -gt 0 ]; then
  echo "check_layers: $violations include(s) break the layer order; see docs/design.md, \"Layers\"" >&2
  exit 1
fi
echo "check_layers: every include follows the layer order of $TABLE"
