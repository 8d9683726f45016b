import subprocess
import sys
import textwrap


def test_every_procgen_module_and_the_sim_free_maths_import_without_sapien_or_maniskill():
    code = textwrap.dedent(
        """
        import importlib.machinery, sys
        path_finder = importlib.machinery.PathFinder.find_spec
        def hide_simulator(cls, name, path=None, target=None):
            if name.split(".")[0] in ("sapien", "mani_skill"):
                return None  # as if SAPIEN and ManiSkill were not installed
            return path_finder(name, path, target)
        importlib.machinery.PathFinder.find_spec = classmethod(hide_simulator)
        import importlib, pkgutil
        import mani_skill_space.procgen
        modules = [m.name for m in pkgutil.iter_modules(mani_skill_space.procgen.__path__, "mani_skill_space.procgen.")]
        assert len(modules) >= 14, modules
        for name in [*modules, "mani_skill_space.domains", "mani_skill_space.rewards", "mani_skill_space.geometry", "mani_skill_space.levels", "mani_skill_space.factors", "mani_skill_space.delay", "mani_skill_space.kwarg_checks", "mani_skill_space.debris_paths"]:
            importlib.import_module(name)
        assert "sapien" not in sys.modules and "mani_skill" not in sys.modules
        mani_skill_space.procgen.rock.make_rock(0)
        print("ok")
        """
    )
    result = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip().endswith("ok")
