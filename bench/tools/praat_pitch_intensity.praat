# Praat's pitch + intensity only (for timing against kinemo).
form Timing
  sentence Infile
endform
sound = Read from file: infile$
pitch = To Pitch (ac): 0.01, 75, 15, "no", 0.03, 0.45, 0.01, 0.35, 0.14, 600
selectObject: sound
intensity = To Intensity: 75, 0.01, "yes"
