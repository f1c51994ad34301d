%areas_two_path
; Seed 000 §2.4 "Defining a workspace for a 2-path application", verbatim (N040-N110),
; then monitored: run with --machine examples/machines/two_path.toml
N040 #CONTROL AREA START [ID=1 WORK MONITOR_LVL = "IMCS" POLY MIN_EXCUR
= -100 MAX_EXCUR = 100]
N050 : G0 X200 Y0 : G0 U150 V0
N060 : G0 X200 Y200 : G0 U150 V150
N070 : G0 X-200 Y200 : G0 U-150 V150
N080 : G0 X-200 Y-200 : G0 U-150 V-150
N090 : G0 X200 Y-200 : G0 U150 V-150
N100 : G0 X200 Y0 : G0 U150 V0
N110 #CONTROL AREA END
N120 #CONTROL AREA ON [ID=1]
N130 G01 F3000 : X100 Y100 : U100 V100
N140 #MSG SYN ["U=%f V=%f", V.A.ABS.U, V.A.ABS.V]
; The secondary path would leave the IMCS workspace at U = 150: error 900317, not executed
N150 : X300 : U200
N160 M30
