import os
from pathlib import Path

import numpy as np
import pytest

from nsga_jax._compilation_cache import ENV
from nsga_jax._process_settings import configure_jax

configure_jax()  # float64 and XLA's CPU flag, as the command line sets them (importing nsga_jax sets neither)

QUICK_COMPILE = "--xla_backend_optimization_level=0"
TESTS = Path(__file__).resolve().parent


def pytest_configure(config):
    """The default suite (``-m 'not slow'``) checks numbers, not speed: XLA's
    CPU backend compiles its many small programs without LLVM's optimisation
    passes (a quarter less time for the suite on 2 cores). Round-off may differ
    in the last bits (no fused multiply-adds), so the slow suite (``-m slow``,
    which CI also runs) keeps XLA's default, the programs users run. Set
    before the first computation, for this process, its test processes and
    the command-line runs it starts; a flag already in ``XLA_FLAGS`` wins."""
    quick = config.getoption("markexpr", "") == "not slow"
    if quick and "xla_backend_optimization_level" not in os.environ.get("XLA_FLAGS", ""):
        os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {QUICK_COMPILE}".strip()


MAX_WORKERS = 4


def pytest_xdist_auto_num_workers(config):
    """``-n auto`` (the default, pyproject.toml): one test process per core this
    process may use, at most :data:`MAX_WORKERS` (``PYTEST_XDIST_AUTO_NUM_WORKERS``
    overrides) (each holds its files' compiled programs); each
    process runs whole files (``--dist loadfile``), so a file's module fixtures
    compile once."""
    if os.environ.get("PYTEST_XDIST_AUTO_NUM_WORKERS"):
        return int(os.environ["PYTEST_XDIST_AUTO_NUM_WORKERS"])
    return max(1, min(len(os.sched_getaffinity(0)), MAX_WORKERS))


@pytest.fixture(autouse=True)
def _seed():
    np.random.seed(0)


@pytest.fixture(autouse=True, scope="session")
def _compilation_cache(tmp_path_factory):
    """Command-line runs (here and in subprocesses) keep their compiled programs
    in a folder of the test session, never in the user's cache."""
    os.environ[ENV] = str(tmp_path_factory.mktemp("xla_cache"))


@pytest.fixture
def scene_registry():
    """The scenes a test registers (system files, scene files) stay out of the
    other tests' registry: it is restored after the test."""
    from nsga_jax._scenes.files import _SCENE_FILES
    from nsga_jax.scenes import REGISTRY

    before, files = dict(REGISTRY), dict(_SCENE_FILES)
    yield REGISTRY
    REGISTRY.clear()
    REGISTRY.update(before)
    _SCENE_FILES.clear()  # a scene file whose scenes left the registry is imported again when next named
    _SCENE_FILES.update(files)


@pytest.fixture
def no_compilation(monkeypatch):
    """Any attempt to lower or compile a run's programs fails the test: for
    tests that input is refused before anything is compiled."""
    import nsga_jax._simulate as simulate_module

    class Forbidden:
        def lower(self, *args, **kwargs):
            raise AssertionError("compilation started before validation finished")

        __call__ = lower

    monkeypatch.setattr(simulate_module, "_prepare_and_init", Forbidden())
    monkeypatch.setattr(simulate_module, "_run_chunk_jit", Forbidden())


LONG = {
    "test_scene_defaults.py::test_every_scene_runs_at_its_defaults",
    "test_scene_defaults.py::test_scenes_with_friction_run_at_their_defaults",
    # Tests of 4 s or more on a 2-core machine (pytest --durations), run by `pytest -m slow`
    # (CI runs both suites); each feature keeps a quicker test in the default run.
    "test_assembly.py::test_fast_path_equals_generic_path",
    "test_system_rigid.py::test_system_run_equals_the_hand_written_model",
    "test_system_rigid.py::test_revolute_joint_holds_and_keeps_the_motion_in_its_plane",
    "test_system_rigid.py::test_spherical_joint_holds_and_keeps_the_vertical_angular_momentum",
    "test_system_rigid.py::test_welded_bodies_move_as_one",
    "test_system_rigid.py::test_model_functions_equal_the_hand_written_ones[rigid_box]",
    "test_cli.py::test_later_runs_load_compiled_programs_from_the_cache",
    "test_extreme.py::test_box_dropped_flat_lands_on_four_vertices_at_once",
    "test_extreme.py::test_stiff_bar_at_a_large_step",
    "test_newton.py::test_reuse_gives_the_trajectory_of_newtons_method",
    "test_stack.py::test_a_stack_stays_at_rest[3-2]",  # 3D boxes: some 80 ms a step on 2 cores; 2D stays quick
    "test_redundant_3d.py::test_a_door_on_two_hinges_swings_as_on_one",  # the reports stay quick
    "test_redundant_3d.py::test_a_four_bar_built_in_3d_keeps_its_plane_and_its_crank_rocker_relation",
    "test_redundant_constraints.py::test_redundant_closed_loop_moves_as_the_loop_without_its_redundant_rod",
    "test_redundant_constraints.py::test_initial_acceleration_is_finite_and_differentiable_in_float32",
    "test_redundant_constraints.py::test_every_member_of_a_batch_carries_the_redundancy_in_its_warnings",
    "test_mechanisms.py::test_slider_crank_joints_hold_and_the_stop_is_not_penetrated",
    "test_mechanisms.py::test_slider_crank_starts_on_the_rigid_mechanism_and_follows_it_before_the_impact",
    "test_mechanisms.py::test_slider_crank_energy_does_not_grow_through_impacts",
    "test_mechanisms.py::test_free_slider_crank_without_stop_and_gravity_conserves_energy",
    "test_mechanisms.py::test_ds_converges_where_cs_fails_at_a_large_step",
    "test_mechanisms.py::test_appendage_tip_stays_admissible_and_the_clamp_holds",
    "test_mechanisms.py::test_appendage_energy_does_not_grow",
    "test_mechanisms.py::test_appendage_starts_as_a_rigid_rotation",
    "test_mechanisms.py::test_variants_build_consistently",
    "test_performance.py::test_generic_path_keeps_nothing_constant",
    "test_event_gradients.py::test_pendulum_event_gradient_in_wall_position",
    "test_event_gradients.py::test_ball_event_gradient_converges_to_the_exact_derivative",
    "test_event_gradients.py::test_event_gradient_forward_equals_reverse",
    "test_event_gradients.py::test_away_from_impacts_both_adjoints_agree",
    "test_gradients.py::test_rigid_box_restitution_against_fd",
    "test_gradients.py::test_bar_reverse_equals_forward",
    "test_gradients.py::test_rigid_pendulum_against_fd",
    "test_gradients.py::test_bar_tip_displacement_against_fd",
    "test_gradients.py::test_checkpointing_choices_give_the_same_gradient",
    "test_gradients.py::test_spectral_radius_is_differentiable",
    "test_identify.py::test_cli_identify_synthetic_then_from_file",
    "test_integrate.py::test_integrate_under_jit_equals_simulate[impacting_bar-overrides1]",
    "test_identify.py::test_adam_also_descends",
    "test_identify.py::test_a_start_30_percent_above_recovers_the_restitution",
    "test_newton.py::test_gradients_with_reused_factorisations",
    "test_newton.py::test_reused_subproblems_are_those_left_non_constant",
    "test_newton.py::test_a_batch_with_held_factorisations_equals_single_runs",
    "test_own_model.py::test_cli_identify_recovers_restitution",
    "test_own_model.py::test_cli_run",
    "test_own_model.py::test_cli_convergence",
    "test_own_model.py::test_cli_sweep",
    "test_own_model.py::test_impact_against_event_driven_reference",
    "test_own_model.py::test_smooth_motion_matches_the_angle_equations_to_second_order",
    "test_paper_scenes.py::test_flexible_cube_impact_window",
    "test_paper_scenes.py::test_flexible_pendulum_paper_run",
    "test_performance.py::test_device_check_agreement_runs",
    "test_system_files.py::test_gradient_of_a_dotted_parameter_matches_finite_differences",
    "test_system_files.py::test_the_examples_run",
    "test_system_files.py::test_a_system_file_runs",
    "test_system_files.py::test_a_sweep_over_a_dotted_path",
    "test_system_files.py::test_identify_recovers_a_dotted_parameter",
    "test_system_files.py::test_convergence_of_a_system_file",
    "test_performance.py::test_bench_writes_its_table",
    "test_performance.py::test_fast_paths_agree_for_other_schemes",
    "test_performance.py::test_fast_paths_agree_with_generic_path",
    "test_performance.py::test_a_batch_is_skipped_on_its_probes_estimate",
    "test_precision_and_records.py::test_float32_run_converges_and_follows_float64",
    "test_precision_and_records.py::test_float32_failure_message_names_the_precision",
    "test_readme.py::test_example_runs_as_written[docs/gradients.md: Gradients through whole trajectories]",
    "test_readme.py::test_example_runs_as_written[docs/sweeps-and-devices.md: Sweeps]",
    "test_readme.py::test_example_runs_as_written[docs/own-model.md: 4. From Python]",
    "test_event_gradients.py::test_other_schemes_event_gradient[DSn]",
    "test_rigid_box.py::test_free_flight_conserves_energy_and_angular_momentum",
    "test_rigid_box.py::test_flight_before_impact_matches_rigid_body_ode",
    "test_studies.py::test_vmap_over_step_sizes_equals_separate_runs",
    "test_sweep.py::test_sharded_sweep_equals_unsharded",
    "test_sweep.py::test_sweep_over_two_processes_equals_one_process",
    "test_sweep.py::test_two_processes_resume_as_process_0_decides",
    "test_sweep.py::test_failed_runs_are_reported",
    "test_sweep.py::test_rigid_box_sweep_equals_single_runs",
    "test_event_gradients.py::test_other_schemes_event_gradient[MJ]",
    "test_impact_time_friction.py::test_disk_slipping_through_the_impact",
    "test_impact_time_friction.py::test_disk_slipping_through_the_impact_with_the_other_schemes",
    "test_impact_time_friction.py::test_disk_sticking_at_the_impact",
    "test_impact_time_friction.py::test_disk_landing_and_sliding_on",
    "test_impact_time_friction.py::test_discrete_adjoint_misses_the_impact_instant",
    "test_impact_time_friction.py::test_sphere_slipping_through_the_impact",
    "test_check_model.py::test_built_in_models_keep_their_declarations[flexible_cube]",
    "test_integrate.py::test_saveat_fn_keeps_what_a_loss_needs_under_grad",
    "test_integrate.py::test_integrate_with_members_sharded_over_two_devices",
    "test_gradients.py::test_vmap_of_grad_equals_grad",
    "test_gradients.py::test_reverse_equals_forward",
    "test_readme.py::test_example_runs_as_written[docs/python-api.md: Output control: `SaveAt`]",
    "test_system_flexible.py::test_rebuilt_scene_runs_as_the_old_model_bit_for_bit",
    "test_newtons_cradle.py::test_last_ball_leaves_with_the_first_ones_velocity",
    "test_newtons_cradle.py::test_momentum_exact_and_energy_kept",
    "test_newtons_cradle.py::test_positions_follow_the_collision_sequence",
    "test_newtons_cradle.py::test_collisions_inside_steps_shift_the_motion_by_less_than_a_step_each",
    "test_double_pendulum.py::test_reference_keeps_energy_between_impacts_and_loses_newtons_share",
    "test_double_pendulum.py::test_angles_converge_to_the_reference_before_and_after_the_impact",
    "test_double_pendulum.py::test_joints_hold_and_the_tip_never_penetrates",
    "test_double_pendulum.py::test_energy_never_grows_at_the_impact",
    "test_readme.py::test_example_runs_as_written[docs/newtons-cradle.md: In Python]",
    "test_readme.py::test_example_runs_as_written[docs/double-pendulum.md: In Python]",
    # The default suite's 5-minute aim (2026-12-04, two test processes on 2 cores): tests of about
    # 5 s or more there; their files keep quicker tests of the same features in the default run.
    "test_stack.py::test_a_stack_stays_at_rest[2-3]",
    "test_readme.py::test_example_runs_as_written[docs/python-api.md: Running a model: `integrate` and `simulate`]",
    "test_system_parts.py::test_joints_hold_and_contacts_do_not_penetrate_through_a_run",
    "test_redundant_constraints.py::test_pinned_twice_moves_as_pinned_once[ds]",
    "test_redundant_constraints.py::test_the_command_line_prints_the_redundancy_once_in_its_own_words",
    "test_readme.py::test_example_runs_as_written[docs/system-files.md: From Python]",
    "test_fuzz.py::test_ctrl_c_stops_cleanly_and_says_what_was_kept",
    "test_check_model.py::test_built_in_models_keep_their_declarations[box_stack]",
    "test_check_model.py::test_built_in_models_keep_their_declarations[flexible_appendage]",
    "test_check_model.py::test_built_in_models_keep_their_declarations[flexible_pendulum]",
    "test_performance.py::test_no_recompilation_when_only_h_or_parameters_change",
    "test_energetic_impact.py::test_equal_to_newtons_law_where_it_creates_no_energy[sliding_no_reversal]",
    "test_energetic_impact.py::test_newtons_law_creates_energy_where_the_energetic_law_does_not",
    "test_sweep.py::test_a_member_whose_exact_motion_is_zero_keeps_the_sweep_going",
    "test_sweep.py::test_killed_sweep_resumes_to_the_same_table",
    "test_krylov.py::test_cube_matches_the_dense_path_at_the_default_tolerance",
    "test_krylov.py::test_no_n_by_n_array_is_formed",
    "test_krylov.py::test_the_switch_follows_the_model_structure_and_size",
    "test_krylov.py::test_closed_form_hex8_force_and_stiffness_equal_the_energy_derivatives",
    "test_krylov.py::test_memory_estimate_of_the_matrix_free_path_is_linear",
    "test_krylov.py::test_kronecker_mass_is_exact_and_preconditions_the_velocity_jump",
    "test_own_model.py::test_rods_hold_at_position_and_velocity_level",
    "test_fuzz.py::test_energy_created_at_an_impact_is_named_and_strict_fails",
    "test_fuzz.py::test_float32_time_is_t0_plus_k_h_not_accumulated",
    "test_fuzz.py::test_default_runs_keep_their_invariants[impacting_bar-overrides2]",
    "test_fuzz.py::test_default_runs_keep_their_invariants[rigid_pendulum-overrides1]",
    "test_friction.py::test_glancing_impact_of_two_discs[DS]",
    "test_friction.py::test_2d_box_slides_stops_and_rests[DS]",
    "test_friction.py::test_block_on_an_incline[CS-0.29-0.3-0.0]",
    "test_friction.py::test_block_on_an_incline[DSn-0.29-0.3-0.0]",
    "test_friction.py::test_3d_point_mass_keeps_its_sliding_direction[DS]",
    "test_friction.py::test_oblique_impact_of_a_point_mass[3d-slip-DS]",
    "test_friction.py::test_oblique_impact_of_a_point_mass[2d-slip-DS]",
    "test_friction_scenes.py::test_incline_follows_the_exact_sliding_law[slides-down]",
    "test_friction_scenes.py::test_spin_turns_into_horizontal_velocity_at_the_impact[30.0-False]",
    "test_system_parts.py::test_derived_structure_is_what_the_functions_do",
    "test_validation.py::test_model_fields_of_every_scene_are_checked",
    "test_precision_and_records.py::test_float32_run_computes_in_float32_with_x64_on[impacting_bar]",
    "test_precision_and_records.py::test_float32_run_computes_in_float32_with_x64_on[flexible_pendulum]",
    "test_precision_and_records.py::test_float32_run_computes_in_float32_with_x64_on[flexible_cube]",
    "test_system_flexible.py::test_rebuilt_scene_has_the_old_models_structure[flexible_cube]",
    "test_system_files.py::test_cli_runs_a_system_file",
    "test_readme.py::test_example_runs_as_written[docs/friction.md: Coulomb friction]",
    "test_identify.py::test_a_fit_stopped_on_a_flat_bound_is_reported_as_failed",
    "test_identify.py::test_ball_restitution_and_height_recovered[1% noise]",
    "test_extreme.py::test_redundant_contacts_with_the_other_schemes[cs]",
    "test_performance.py::test_record_template_matches_the_step[rigid_box-ds]",
    "test_cli_options.py::test_no_plots_writes_the_data_and_no_png[identify]",
    "test_studies.py::test_reference_run_and_grid_sampling",
    "test_fuzz.py::test_default_runs_keep_their_invariants[rigid_box-overrides3]",
    "test_energetic_impact.py::test_equal_to_newtons_law_where_it_creates_no_energy[sticking_e0]",
    "test_schemes.py::test_cs_agrees_with_ds_at_small_step",
    "test_impacting_bar.py::test_lumped_mass_variant_runs",
    "test_krylov.py::test_projected_bordered_solve_equals_the_schur_complement",
    "test_readme.py::test_example_runs_as_written[docs/systems.md: A first system]",
    "test_energetic_impact.py::test_the_share_is_differentiable",
    "test_energetic_impact.py::test_dsn_carries_the_law_and_gravity_leaves_the_steps_own_error",
    # The default suite's tests of 14 s or more (2026-12-06, `pytest --durations=60`, two test
    # processes with a benchmark beside them; the suite took 855 s). Kept in the default run of
    # their features: impacts at their instants on the ball (DS, DSn, float32, coming to rest, every
    # driver), the block elimination's solves and gradient, the warm start's start rule, the stack
    # at rest, the restarts on their own problems in test_newton.py.
    "test_structured.py::test_adjoints_equal_the_dense_paths",  # 105 s
    "test_structured.py::test_a_chain_runs_as_on_the_dense_path[DS]",  # 22 s
    "test_impact_instants.py::test_batch_of_rocking_blocks_splits_each_member_as_its_own_run",  # 93 s
    "test_impact_instants.py::test_gradient_through_the_located_instant_is_the_exact_one",  # 70 s
    "test_impact_instants.py::test_sweep_convergence_and_identify_carry_the_option",  # 62 s
    "test_impact_instants.py::test_slider_crank_stop_keeps_the_energy_of_its_elastic_impacts",  # 50 s
    "test_impact_instants.py::test_matrix_free_cube_locates_its_landing_as_the_dense_path",  # 50 s
    "test_impact_instants.py::test_double_pendulum_converges_at_second_order_through_its_impact",  # 46 s
    "test_impact_instants.py::test_event_adjoint_rebuilds_the_impacts_a_paper_step_takes_under_the_option",  # 41 s
    "test_impact_instants.py::test_spinning_box_rebounds_with_its_restitution",  # 24 s
    "test_impact_instants.py::test_newtons_cradle_follows_the_exact_sequence_of_collisions",  # 14 s
    "test_warm_start.py::test_a_pushed_stack_is_the_same_motion_in_fewer_iterations",  # 41 s
    "test_warm_start.py::test_a_sub_problem_that_fails_hands_zero_to_the_next_step",  # 17 s
    "test_sweep_build.py::test_system_file_sweep_is_traced_and_equals_single_runs",  # 29 s
    "test_energetic_impact.py::test_equal_to_newtons_law_where_it_creates_no_energy[no_slip]",  # 18 s
    "test_stack.py::test_the_step_that_cycled_converges_without_a_restart",  # 16 s and 14 s
    "test_krylov.py::test_cube_warm_started_on_the_matrix_free_path_is_the_same_run",  # 15 s
}


# The longest checks of the slow suite, over CI's 90 minutes on 2 cores when the
# rest runs there too: marked ``long`` as well as ``slow``. ``pytest -m slow``
# (by hand) runs them with the rest, ``pytest -m long`` alone; ``.ci/run`` runs
# ``-m "slow and not long"``. Each feature keeps a check in CI, named after the
# test (seconds: two slow-suite files at once on 2 cores, 2026-12-06).
OVER_CI_BUDGET = {
    # 290 s; the gradient through a located instant against the exact one (the ball) stays
    "test_impact_instants.py::test_gradient_through_instants_located_on_the_smooth_motion_matches_finite_differences",
    # 130 s and 112 s; the discrete adjoint on the matrix-free path stays (83 s)
    "test_krylov.py::test_gradients_through_the_landing_match_the_dense_path[dsn-impact_time]",
    "test_krylov.py::test_gradients_through_the_landing_match_the_dense_path[impact_time]",
    # 124 s; a sweep of the matrix-free cube (batched members) stays (38 s)
    "test_krylov.py::test_a_batch_equals_its_single_runs",
    # 105 s; the energetic law's runs and cone checks stay
    "test_energetic_impact.py::test_the_share_is_differentiable",
    # 75 s; the same gradient with the discrete adjoint stays (58 s)
    "test_friction.py::test_gradient_of_the_sliding_distance[impact-time]",
    # 73 s; the disk slipping through the impact (3 schemes) stays
    "test_impact_time_friction.py::test_sphere_slipping_through_the_impact",
    # 302 s, 163 s and 132 s (three processes at once); the planar chain in every scheme, the ring,
    # float32, batches and the discrete adjoint on the block-tridiagonal path stay
    "test_structured.py::test_adjoints_equal_the_dense_paths[impact-time]",
    "test_structured.py::test_a_3d_chain_of_hinged_links_runs_as_on_the_dense_path",
    "test_structured.py::test_impacts_at_their_instants_run_as_on_the_dense_path",
    # about 200 s (3 s of a 10-box stack); a pushed stack of three coming to rest in 2D and 3D stays
    "test_stack.py::test_ten_pushed_planar_boxes_come_to_rest_without_a_failed_step",
    # over 600 s with two other files running (the landing's sticking and slipping nodes of a dense
    # 648-unknown cube); friction on 3D boxes, the box and the ball at their defaults stay
    "test_scene_defaults.py::test_scenes_with_friction_run_at_their_defaults[flexible_cube]",
}


@pytest.hookimpl(tryfirst=True)
def pytest_collection_modifyitems(config, items):
    """Mark the tests named in :data:`LONG` slow and those in
    :data:`OVER_CI_BUDGET` slow and long (every parametrization of a
    function, or one parametrization named with its id), before ``-m``
    selects. Where the whole suite is collected, a name that matches no test
    (renamed, removed, misspelt) stops the run with its name."""
    matched = set()
    for item in items:
        path, _, rest = item.nodeid.partition("::")
        test = f"{path.split('/')[-1]}::{rest}"
        names = {test, test.split("[")[0]}
        if names & LONG:
            item.add_marker(pytest.mark.slow)
        if names & OVER_CI_BUDGET:
            item.add_marker(pytest.mark.slow)
            item.add_marker(pytest.mark.long)
        matched |= names
    whole_suite = all(Path(arg).resolve() == TESTS for arg in config.args)
    unmatched = sorted((LONG | OVER_CI_BUDGET) - matched)
    if whole_suite and unmatched:
        raise pytest.UsageError(f"tests/conftest.py names tests that do not exist: {', '.join(unmatched)}")
