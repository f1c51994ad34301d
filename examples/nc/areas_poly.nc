%areas_poly
; Workspace and protection area (seed 000 §3.1): the polygonal workspace ID3 of §3.1.1 (with its
; notch X-50..50 Y0..75) and a cylindrical protection area ID4 (centre X100 Y50, radius 20).
; The arc N230 starts and ends inside the workspace and outside ID4, but its bulge dips into ID4:
; block preparation refuses it and the program aborts.
; Draw it: fieldprobe areas plot examples/nc/areas_poly.nc --out areas.svg
N10 G00 G90 X-100 Y50 Z0
N20 #CONTROL AREA BEGIN [ID3 WORK POLY MIN_EXCUR=-50 MAX_EXCUR=50]
N30 G01 F1000 G90 X-150 Y75 (Starting point)
N40 X-50 Y150
N50 X50 Y150
N60 X150 Y75
N70 X150 Y0
N80 X50 Y0
N90 X50 Y75
N100 X-50 Y75
N110 X-50 Y0
N120 X-150 Y0
N130 X-150 Y75 (End point identical with starting point)
N140 #CONTROL AREA END
N150 #CONTROL AREA BEGIN [ID4 PROT CIRC MIN_EXCUR=-70 MAX_EXCUR=70]
N160 G01 X100 Y30 F10000 (Start point of the circle)
N170 G02 G162 I0 J20 (Full circle: centre X100 Y50, radius 20)
N180 #CONTROL AREA END
N190 #CONTROL AREA ON [ID3]
N200 #CONTROL AREA ON [ID4]
N210 G01 X-100 Y90 F3000
N220 X75
N230 G03 X125 Y90 I25 J0 (lowest point X100 Y65: inside ID4)
N240 #MSG SYN["not reached"]
N250 M30
