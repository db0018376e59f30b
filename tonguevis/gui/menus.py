"""The main window's menus and its recent-files list (QSettings), as a mixin of MainWindow."""

from __future__ import annotations

from pathlib import Path

from PySide6.QtGui import QAction, QActionGroup, QKeySequence

from tonguevis.appstate import COLOR_MODES, REFERENCE_FRAMES, connected
from tonguevis.gui.view3d import COLOUR_LABELS, REFERENCE_LABELS

MAX_RECENT = 8


class MenusMixin:
    """Needs ``self.state``, ``self.preferences``, ``self.view3d``, ``self.transport`` and the
    window's open/export/rest methods.  The Simulation menu's items write the app model's run settings;
    their check marks follow its ``run_settings`` events (:meth:`_reflect_run_settings`), whoever changed them."""

    def _build_menus(self) -> None:
        bar = self.menuBar()
        file_menu = bar.addMenu("&File")
        self._action(file_menu, "&Open recording…", self.ask_open_recording, QKeySequence.StandardKey.Open)
        self._action(file_menu, "Open recording with &sound/labels…", self.ask_open_with_companions)
        self._action(file_menu, "Open &mesh…", self.ask_open_mesh)
        self.recent_menu = file_menu.addMenu("Open &recent")
        self._fill_recent()
        self._action(file_menu, "Open &demo", self.open_demo)
        self._action(file_menu, "&Compare with another recording…", self.ask_compare)
        self._action(file_menu, "S&top comparing", self.stop_comparing)
        self._action(file_menu, "Connect to &live source…", self.open_live_window)
        file_menu.addSeparator()
        self._action(file_menu, "Load &palate…", self.ask_load_palate)
        self._action(file_menu, "&Fit palate from traces…", self.ask_fit_palate)
        self._action(file_menu, "Use the &generic palate (contact on)", self.use_generic_palate)
        self._action(file_menu, "&No palate (contact off)", self.use_no_palate)
        file_menu.addSeparator()
        self._build_export_menu(file_menu.addMenu("&Export"))
        file_menu.addSeparator()
        self._action(file_menu, "&Quit", self.close, QKeySequence.StandardKey.Quit)
        view = bar.addMenu("&View")
        self._action(view, "&Reset camera", self.view3d.reset_camera, "R")
        context = self._action(view, "Show &jaw and palate", lambda: None, "J")
        context.setCheckable(True)
        context.setChecked(True)
        context.toggled.connect(self.view3d.set_context_visible)
        self.context_action = context
        group = QActionGroup(self)
        for mode in COLOR_MODES:
            action = self._action(view, f"Colour by {COLOUR_LABELS[mode]}", lambda m=mode: self.state.set_color(m))
            action.setCheckable(True)
            action.setChecked(mode == self.state.color)
            group.addAction(action)
        view.addSeparator()
        frames = QActionGroup(self)
        self.reference_actions = {}
        for frame, key in zip(REFERENCE_FRAMES, ("H", "Shift+H")):
            action = self._action(view, REFERENCE_LABELS[frame].capitalize(),
                                  lambda f=frame: self.state.set_reference(f, self), key)
            action.setCheckable(True)
            action.setChecked(frame == self.state.reference)
            frames.addAction(action)
            self.reference_actions[frame] = action
        connected(self.state.events.reference, lambda event: self.reference_actions[event.value].setChecked(True))
        simulation = bar.addMenu("&Simulation")
        self.rest_action = self._action(simulation, "Set &rest interval…", self.ask_rest_interval)
        self.patches_action = QAction("Sensors on the &surface (sensor patches)", self)
        self.patches_action.setCheckable(True)
        self.patches_action.setToolTip("close the gap between each sensor and the tongue's surface with the tongue's "
                                       "own local deformation under it (tonguevis simulate --sensor-patches)")
        self.patches_action.triggered.connect(self.set_sensor_patches)
        simulation.addAction(self.patches_action)
        self.rest_fit_action = QAction("&Fit the tongue to the rest sensors", self)
        self.rest_fit_action.setCheckable(True)
        self.rest_fit_action.setToolTip("bend the tongue so that every sensor node sits on its rest sensor before "
                                        "simulating (tonguevis simulate --fit-rest): the speaker's rest shape")
        self.rest_fit_action.triggered.connect(self.set_rest_fit)
        simulation.addAction(self.rest_fit_action)
        self.closures_action = QAction("&Press the closures onto the palate", self)
        self.closures_action.setCheckable(True)
        self.closures_action.setToolTip("with a palate: at each /t/ closure the part of the tongue ahead of the tip "
                                        "sensor, at each /k/ closure the dorsum about its sensor, is pressed onto "
                                        "the palate (off: tonguevis simulate --no-closures)")
        self.closures_action.triggered.connect(self.set_closures)
        simulation.addAction(self.closures_action)
        self.humps_action = QAction("Move the tissue around each sensor as a &hump", self)
        self.humps_action.setCheckable(True)
        self.humps_action.setToolTip("the tongue around each coil but the tip's rises with it, flattened against the "
                                     "palate (off: a peak under each coil; tonguevis simulate --no-humps)")
        self.humps_action.triggered.connect(self.set_humps)
        simulation.addAction(self.humps_action)
        self.method_actions = self._choice_menu(simulation, "&Method", (
            ("warped", "&Modal warping (the paper)", "linear FEM modes made nonlinear by modal warping (Yang 2013)"),
            ("linear", "&Linear modes", "the linear modal model, no warping"),
            ("domains", "&Nonlinear tissue on quadratic domains (slower)",
             "nonlinear tissue (StVK) on quadratic domains, after Luo et al. 2017: a few hundred frames/s, "
             "the modal methods thousands (tonguevis simulate --method domains)")),
            None, self.set_method)
        self.size_actions = self._choice_menu(simulation, "Tongue &size", (
            ("adult", "&Adult (the alignment's size when an adult's, else the generic one)",
             "the size the rest sensors' alignment implies when it is an adult tongue's (half to twice the "
             "model's volume), else the generic adult size with the sensors fitted onto its surface"),
            ("alignment", "As the rest a&lignment scales it",
             "the size the rest sensors' fit onto the model's placement rule implies, whatever it is "
             "(tonguevis simulate --tongue-size alignment)"),
            ("generic", "&Generic adult tongue (about 100 cm³)",
             "the model's own size, turned and moved so the rest sensors lie on its upper surface "
             "(tonguevis simulate --tongue-size 1)")),
            None, self.set_tongue_size)
        self._reflect_run_settings()
        connected(self.state.events.run_settings, self._reflect_run_settings)
        play = bar.addMenu("&Playback")
        self._action(play, "&Play / pause", lambda: self.state.toggle_playing(self), "Space")
        self._action(play, "Step &forward", lambda: self.state.step(1, self), "Right")
        self._action(play, "Step &back", lambda: self.state.step(-1, self), "Left")
        self._action(play, "&Loop current production", self.transport.loop.toggle, "L")

    def _choice_menu(self, parent, title: str, items, current, choose) -> dict:
        """A submenu ``title`` of ``parent`` with one checkable item per (key, text, tip) of ``items``, one
        checked at a time (``current``'s); triggering one calls ``choose(key)``.  Returns {key: action}."""
        menu = parent.addMenu(title)
        group = QActionGroup(self)
        actions = {}
        for key, text, tip in items:
            action = QAction(text, self)
            action.setCheckable(True)
            action.setToolTip(tip)
            action.setChecked(key == current)  # None: the run settings' events check one
            action.triggered.connect(lambda _checked=False, key=key: choose(key))
            group.addAction(action)
            menu.addAction(action)
            actions[key] = action
        menu.setToolTipsVisible(True)
        return actions

    def _reflect_run_settings(self, _event=None) -> None:
        """The Simulation menu's check marks as the app model's run settings say (programmatic checks: only a
        user's click triggers an item, so nothing is written back)."""
        settings = self.state.run_settings
        self.patches_action.setChecked(settings.sensor_patches is not None)
        self.closures_action.setChecked(bool(settings.closures))
        self.humps_action.setChecked(bool(settings.humps))
        self.humps_action.setEnabled(settings.sensor_patches is not None)
        self.rest_fit_action.setChecked(bool(settings.rest_fit))
        self.method_actions[settings.method].setChecked(True)
        key = self._tongue_size()
        for name, action in self.size_actions.items():
            action.setChecked(name == key)

    def set_method(self, method: str) -> None:
        """Simulate with ``method`` ("warped", "linear" or "domains") from now on (the open recording again)."""
        self.state.change_run_settings(self, method=method)

    #: Simulation ▸ Tongue size: the menu's keys and the run settings' ``tongue_size``.
    TONGUE_SIZES = {"adult": "adult", "alignment": None, "generic": 1.0}

    def _tongue_size(self) -> str | None:
        """The Tongue size menu's key of the run settings' size (None: a size no item names, e.g. 1.2)."""
        size = self.state.run_settings.tongue_size
        return next((key for key, value in self.TONGUE_SIZES.items() if value == size), None)

    def set_tongue_size(self, key: str) -> None:
        """Simulate at the tongue size ``key`` ("adult", "alignment" or "generic") from now on."""
        self.state.change_run_settings(self, tongue_size=self.TONGUE_SIZES[key])

    def set_closures(self, on: bool) -> None:
        """Press (or not) the tongue onto the palate at the closures from now on."""
        self.state.change_run_settings(self, closures=bool(on))

    def set_humps(self, on: bool) -> None:
        """Simulate with (or without) the sensors' humps from now on."""
        self.state.change_run_settings(self, humps=bool(on))

    def set_sensor_patches(self, on: bool) -> None:
        """Simulate with (or without) the sensor patches from now on."""
        self.state.change_run_settings(self, sensor_patches="default" if on else None)

    def set_rest_fit(self, on: bool) -> None:
        """Simulate with (or without) the rest shape fitted to the rest sensors from now on."""
        self.state.change_run_settings(self, rest_fit=bool(on))

    def _build_export_menu(self, menu) -> None:
        """File ▸ Export: one item per row of the export table (tonguevis.workflows.exports), the same
        table ``tonguevis formats`` prints; each item's tip says what the file holds and the command
        that writes it."""
        from tonguevis.workflows.exports import EXPORTS

        handlers = {"png": self.ask_export_screenshot, "mp4": self.ask_export_video,
                    "xdmf": self.ask_export_paraview, "vtk": self.ask_export_vtk,
                    "csv": lambda: self.ask_export_productions("csv"),
                    "textgrid": lambda: self.ask_export_productions("textgrid"),
                    "wav": lambda: self.ask_export_productions("wav")}
        self.export_actions = {}
        for fmt in EXPORTS:
            action = self._action(menu, f"{fmt.title}…", handlers[fmt.key])
            action.setToolTip(f"{fmt.holds}\n(command line: {fmt.command})")
            action.setStatusTip(fmt.holds)
            self.export_actions[fmt.key] = action
        menu.setToolTipsVisible(True)

    def ask_export_productions(self, key: str) -> None:
        from tonguevis.gui.export import ask_productions

        ask_productions(self, key)

    def ask_export_paraview(self) -> None:
        from tonguevis.gui.export import ask_paraview

        self.export_job = ask_paraview(self) or self.export_job

    def open_live_window(self):
        """File ▸ Connect to live source…: the live view (:mod:`tonguevis.gui.live_window`) in a window of its
        own, to connect from its panel (a device, or ``tonguevis stream FILE``)."""
        from tonguevis.gui.live_window import LiveWindow

        open_ = [w for w in getattr(self, "_live_windows", []) if w.isVisible()]
        if open_:  # the app's model holds one live session: its window is brought up again
            open_[-1].raise_()
            open_[-1].activateWindow()
            return open_[-1]
        # the replay's settings; the session goes into the app's model
        window = LiveWindow(settings=self.state.run_settings.replace(rest=None), state=self.state)
        self._live_windows = [window]
        window.show()
        return window

    def _action(self, menu, text: str, slot, shortcut=None) -> QAction:
        action = QAction(text, self)
        if shortcut is not None:
            action.setShortcut(QKeySequence(shortcut))
        action.triggered.connect(lambda _checked=False: slot())
        menu.addAction(action)
        return action

    def recent_files(self) -> list[str]:
        value = self.preferences.value("recent", [])
        if isinstance(value, str):
            value = [value]
        return [str(v) for v in (value or [])]

    def _remember(self, path: Path) -> None:
        recent = [str(path)] + [p for p in self.recent_files() if p != str(path)]
        self.preferences.setValue("recent", recent[:MAX_RECENT])
        self._fill_recent()

    def _fill_recent(self) -> None:
        self.recent_menu.clear()
        for path in self.recent_files():
            self._action(self.recent_menu, path, lambda p=path: self.open_recording(p))
        self.recent_menu.setEnabled(bool(self.recent_files()))

