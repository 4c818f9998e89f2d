# The markdown table of `tools/run bench accuracy`: the default conversion beside OpenVDB, a row
# each, from the benchmark's CSV (awk -F, -f tools/bench/accuracy_table.awk accuracy.csv).
BEGIN {
  print "| scan | method | seconds | peak MiB | bytes/point | RMS/spacing | max/spacing | seen through, worst view | depth error median |"
  print "|---|---|---:|---:|---:|---:|---:|---:|---:|"
}
NR > 1 && (($2 ~ /^iso/ && $3 == "default") || $2 == "openvdb") {
  what = ($2 == "openvdb") ? "OpenVDB, " $3 : ($2 == "iso" ? "iso, default" : "iso, default, mesh metric")
  seen = ($10 == "") ? "" : sprintf("%.3f %%", $10)
  depth = ($11 == "") ? "" : sprintf("%.2f", $11)
  if ($4 == "") printf "| %s | %s | | | | %.3f | %.2f | | |\n", $1, what, $8, $9
  else printf "| %s | %s | %.2f | %.0f | %.2f | %.3f | %.2f | %s | %s |\n", $1, what, $4, $5, $7, $8, $9, seen, depth
}
