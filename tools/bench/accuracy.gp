# The plot of `tools/run bench accuracy`: RMS distance to the truth against conversion time and
# against size, iso filled, OpenVDB open circles, Open3D's screened Poisson open triangles, a color
# per scan.
# gnuplot -e "csv='accuracy.csv'; out='accuracy.png'" tools/bench/accuracy.gp
set terminal pngcairo size 1400,560 font "DejaVu Sans,11"
set output out
set datafile separator ","
set key outside right top
set logscale xy
set grid
names = "sphere torus cube bunny lion dragon"
set multiplot layout 1,2 title "RMS distance to the truth (mean point spacings) against time and size; filled: iso, circles: OpenVDB, triangles: screened Poisson (Open3D)"
set xlabel "seconds"
set ylabel "RMS / mean spacing"
plot for [i=1:words(names)] csv using (strcol(1) eq word(names,i) && strcol(2) eq "iso" ? $4 : 1/0):8 with points pt 7 lc i title word(names,i), \
     for [i=1:words(names)] csv using (strcol(1) eq word(names,i) && strcol(2) eq "openvdb" ? $4 : 1/0):8 with points pt 6 ps 1.5 lc i notitle, \
     for [i=1:words(names)] csv using (strcol(1) eq word(names,i) && strcol(2) eq "open3d" ? $4 : 1/0):8 with points pt 8 ps 1.5 lc i notitle
set xlabel "bytes per input point"
plot for [i=1:words(names)] csv using (strcol(1) eq word(names,i) && strcol(2) eq "iso" ? $7 : 1/0):8 with points pt 7 lc i title word(names,i), \
     for [i=1:words(names)] csv using (strcol(1) eq word(names,i) && strcol(2) eq "openvdb" ? $7 : 1/0):8 with points pt 6 ps 1.5 lc i notitle, \
     for [i=1:words(names)] csv using (strcol(1) eq word(names,i) && strcol(2) eq "open3d" ? $7 : 1/0):8 with points pt 8 ps 1.5 lc i notitle
unset multiplot
