# The markdown table of `tools/run bench accuracy`: iso's default conversion (its file, and its
# exported mesh under the metric every mesh is measured with) beside OpenVDB and Open3D's screened
# Poisson, a row each, from the benchmark's CSV (awk -F, -f tools/bench/accuracy_table.awk
# accuracy.csv). Errors in point spacings; shares of the samples beyond half a spacing and two.
BEGIN {
  print "| scan | method | seconds | peak MiB | bytes/point | RMS | max | > 0.5 | > 2 | bulk RMS (≤ 2) | seen through, worst view | depth error median |"
  print "|---|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
}
function cell(v, format) { return v == "" ? "" : sprintf(format, v) }
NR > 1 && (($2 ~ /^iso/ && $3 == "default") || $2 == "openvdb" || $2 == "open3d") {
  if ($2 == "openvdb") what = "OpenVDB, " $3
  else if ($2 == "open3d") what = "Poisson, " substr($3, 9)
  else what = ($2 == "iso") ? "iso, file" : "iso, mesh"
  printf "| %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s | %s |\n", $1, what,
    cell($4, "%.2f"), cell($5, "%.0f"), cell($7, "%.2f"), cell($8, "%.3f"), cell($9, "%.2f"),
    cell($12, "%.3f %%"), cell($13, "%.3f %%"), cell($14, "%.3f"), cell($10, "%.3f %%"),
    cell($11, "%.2f")
}
