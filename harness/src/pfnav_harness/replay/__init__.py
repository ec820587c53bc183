"""Looking at runs after the fact: Rerun recordings, videos and the HTML report, all made from a run's log.

`run_log` reads a log and picks the frames, `kinematics` poses the robot's legs from the logged
base pose and joint angles (DART, the URDF the run walked), `recording` writes a Rerun `.rrd`,
`video` an isometric MP4, `html_report` the report page. Nothing here runs inside the
co-simulation loop.
"""
