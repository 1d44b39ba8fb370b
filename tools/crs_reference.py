"""PROJ's inverse of every projected CRS of the crs-definitions tables, for the manual test
`campaign::frame::sweep::every_crs_against_proj` (run with `--ignored`).

usage: python tools/crs_reference.py OUT.csv
Writes, for each CRS pyproj can read: code, easting and northing of its area of use's centre
(pyproj's forward projection of it), and pyproj's inverse of them from the CRS's WKT in the
tables (latitude, longitude, degrees). Needs pyproj.
"""
import csv, glob, os, re, sys, warnings
import pyproj

warnings.filterwarnings('ignore')
tables = glob.glob(os.path.expanduser('~/.cargo/registry/src/*/crs-definitions-0.6.0/src/defs.rs'))
if not tables:
    sys.exit('the crs-definitions 0.6.0 sources are not in ~/.cargo/registry: build lidarsim first')
d = open(tables[0]).read()
rows=re.findall(r'EPSG_(\d+)\|\d+\|"([^"]*)"\|r#"(.*?)"#\|',d)
W=pyproj.CRS('EPSG:4326')
out=csv.writer(open(sys.argv[1],'w'))
for code,p4,wkt in rows:
    if not wkt.startswith('PROJCS['): continue
    try:
        c=pyproj.CRS(wkt); a=pyproj.CRS.from_epsg(int(code)).area_of_use
        lon,lat=(a.west+a.east)/2,(a.south+a.north)/2
        if a.west>a.east: lon=((a.west+a.east+360)/2+180)%360-180
        e,n=pyproj.Transformer.from_crs(W,c,always_xy=True).transform(lon,lat)
        lo,la=pyproj.Transformer.from_crs(c,W,always_xy=True).transform(e,n)
        if all(map(lambda v: v==v and abs(v)<1e12,[e,n,lo,la])): out.writerow([code,repr(e),repr(n),repr(la),repr(lo)])
    except Exception: pass
