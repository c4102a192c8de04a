# Read by ctest after the GoogleTest discovery files (TEST_INCLUDE_FILES, see
# tests/CMakeLists.txt): labels `heavy` the long numeric runs. Each takes 3-30 s
# in Release but 1-5 minutes under ASan+UBSan at -O1, where it exercises no
# code path that a short test does not also run under the sanitizers. So
# scripts/test.sh runs them in the Release flavour only (ctest -LE heavy in the
# ASan flavour). ctest ignores a name that matches no test, so the test
# heavy_tests_all_exist (tests/check_heavy_tests.cmake) fails when one here is stale.
set(IMUEMU_HEAVY_TESTS
  Stream.AttitudeNodesMatchPerSampleSmoothing
  Stream.SelfConsistencyAtEcefOverFourHours
  Stream.EveryOptionStreamsLikeBatch
  Stream.OneHourFlightStreamedEqualsBatchBitForBit
  FlightAccuracy.EcefAllMethods
  Ends.AllSamplesAccelWithinTwiceTheInteriorOnTheFlight
  Pipeline.ClosedFormPositionSmoothingEqualsTheDenseSum
  Cli.ClosedLoopOneHourFlightDriftStaysWithinBounds
  AllanEstimate.NinetyPercentIntervalsCoverTheTruthNinetyPercentOfTheTime
  AllanCovariance.MatchesMonteCarloForEachNoise
  # hours of emulated time per preset (issue 15 acceptance 1)
  AllanPresets.Icm42688pOneHourAt1kHz
  AllanPresets.Adis16470OneDayAt25Hz
  AllanPresets.Stim300EightDaysAt20Hz
  AllanPresets.Hg9900SevenHundredHoursAt1Hz
  # an hour at 200 Hz of coning and of sculling (issue 16 acceptance 1)
  SignalChain.ConingCompensatedIncrementsReproduceTheAttitudeAfterOneHour
  SignalChain.ScullingCompensatedIncrementsReproduceTheVelocityAfterOneHour
  SignalChain.RandomVibrationPsdMatchesItsProfileWithinOneDecibel
  SignalChain.RandomAngularVibrationPsdMatchesItsProfileWithinOneDecibel
  # over 15 s under ASan (27 s and 18 s in the CI of 2026-12-05), pure number
  # crunching through code the short Cli tests also run there (issue 25)
  Cli.DenseKnotsKeepTheEndPaddingBounded
  Cli.TrapQuaternionHoldingEcefAttitudeWarnsWithNumbers
)
if(NOT IMUEMU_HEAVY_LIST_ONLY)
  set_tests_properties(${IMUEMU_HEAVY_TESTS} PROPERTIES LABELS heavy)
endif()
